"""The planar freeflyer of the paper (Eq. 30): state [px, py, theta, vx, vy, omega], body-frame force and
torque input, one RK4 step per control period; in numpy (tests, predictions) and in CasADi (the MPC)."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from impact_env.transport.scenario import Body
from planners.online.mpc_specs import NU, NX, MPCInputError, _vector


def _xdot(x, u, mass_kg: float, inertia_kgm2: float, cos, sin):
    """Right-hand side of Eq. (30) for numpy or CasADi arguments; returns a 6-tuple."""
    c, s = cos(x[2]), sin(x[2])
    return (x[3], x[4], x[5], (c * u[0] - s * u[1]) / mass_kg, (s * u[0] + c * u[1]) / mass_kg, u[2] / inertia_kgm2)


def state_from_sim(row: tuple[float, ...] | np.ndarray) -> np.ndarray:
    """MPC state [px, py, theta, vx, vy, omega] (6,) from a simulator row (x, y, vx, vy, heading, omega).

    ``World.read_state()`` and the observations order a body's velocity BEFORE its heading; the MPC state
    (and :func:`rk4_step`) put the heading third, as in Eq. (30).
    """
    x, y, vx, vy, heading, omega = _vector(row, (NX,), "simulator state row")
    return np.array([x, y, heading, vx, vy, omega])


def rk4_step(state: np.ndarray, wrench: np.ndarray, robot: Body, dt: float) -> np.ndarray:
    """One RK4 step (dt in s) of Eq. (30) with the body-frame wrench (3,) [N, N, N m] held: state (6,) -> (6,)."""
    x = np.asarray(state, dtype=float)
    u = np.asarray(wrench, dtype=float)
    if x.shape != (NX,) or u.shape != (NU,):
        raise MPCInputError(f"rk4_step needs state (6,) and wrench (3,), got {x.shape} and {u.shape}")

    def f(z: np.ndarray) -> np.ndarray:
        return np.array(_xdot(z, u, robot.mass_kg, robot.inertia_kgm2, math.cos, math.sin))

    k1 = f(x)
    k2 = f(x + 0.5 * dt * k1)
    k3 = f(x + 0.5 * dt * k2)
    k4 = f(x + dt * k3)
    return x + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


def _rk4_sx(x: ca.SX, u: ca.SX, robot: Body, dt: float) -> ca.SX:
    def f(z: ca.SX) -> ca.SX:
        return ca.vertcat(*_xdot(z, u, robot.mass_kg, robot.inertia_kgm2, ca.cos, ca.sin))

    k1 = f(x)
    k2 = f(x + 0.5 * dt * k1)
    k3 = f(x + 0.5 * dt * k2)
    k4 = f(x + dt * k3)
    return x + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
