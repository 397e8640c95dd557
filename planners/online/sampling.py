"""Vectorised sampling of a plan's Bezier curves (paper Eq. 8, 11) for the control loop.

``BodyPlan.position`` evaluates one segment at a time with a Python loop and rebuilds the Bernstein
coefficients on every call; the expert samples every body at the MPC's N + 1 horizon nodes every control
step, which made that loop 18 % of a step. :class:`PlanSampler` stacks each body's control points once,
(segments, degree + 1, 2), and evaluates any batch of times with one ``searchsorted`` and one ``einsum``.
A body whose segments have different degrees (a spliced plan can mix them) is degree-elevated to the
largest one, which leaves the curve unchanged.
"""

from __future__ import annotations

from math import comb

import numpy as np

from planners import bezier
from planners.plan import BodyPlan, Plan


class _Body:
    __slots__ = ("knots", "t0", "dur", "cp", "dcp", "coef", "dcoef", "degree", "powers", "dpowers", "last")

    def __init__(self, body: BodyPlan) -> None:
        degree = max(len(s.control_points) - 1 for s in body.segments)
        cps = []
        for s in body.segments:
            cp = np.asarray(s.control_points, float)
            while len(cp) - 1 < degree:
                cp = bezier.elevate(cp)
            cps.append(cp)
        self.degree = degree
        self.cp = np.stack(cps)  # (S, d + 1, 2)
        self.t0 = np.array([s.t0_s for s in body.segments])
        self.dur = np.array([s.duration_s for s in body.segments])
        self.knots = np.append(self.t0, body.segments[-1].t1_s)
        self.dcp = degree * np.diff(self.cp, axis=1) / self.dur[:, None, None]  # real velocity (m/s)
        self.coef = np.array([comb(degree, k) for k in range(degree + 1)], float)
        self.dcoef = np.array([comb(degree - 1, k) for k in range(degree)], float)
        # the exponents (k, d - k) of the two bases, looked up once rather than per call
        self.powers = bezier._binomials(degree)[:2]
        self.dpowers = bezier._binomials(max(degree - 1, 0))[:2]
        self.last = len(self.t0) - 1


def _basis(coef: np.ndarray, powers: tuple[np.ndarray, np.ndarray], s: np.ndarray, rest_s: np.ndarray) -> np.ndarray:
    """C(d, k) (1 - s)^(d - k) s^k, with ``s`` and ``rest_s`` = 1 - s given as columns (n, 1)."""
    k, rest = powers
    return coef * rest_s ** rest * s ** k


class PlanSampler:
    """Positions and velocities of a plan's bodies at batches of times, right-continuous at knots (the
    post-impact velocity at an impact time), as :meth:`planners.plan.BodyPlan.position` / ``velocity``."""

    def __init__(self, plan: Plan) -> None:
        self.plan = plan
        self._bodies = {name: _Body(b) for name, b in plan.bodies.items()}

    def _locate(self, b: _Body, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        # np.minimum(np.maximum(...)) is np.clip without its argument handling (a third of this call)
        idx = np.minimum(np.maximum(b.knots.searchsorted(times, side="right") - 1, 0), b.last)
        s = np.minimum(np.maximum((times - b.t0[idx]) / b.dur[idx], 0.0), 1.0)
        return idx, s

    def state(self, name: str, times: np.ndarray) -> np.ndarray:
        """[x, y, vx, vy] (m, m/s) of body ``name`` at each time: shape (len(times), 4)."""
        b = self._bodies[name]
        times = np.asarray(times, float)
        idx, s = self._locate(b, times)
        s = s[:, None]
        rest_s = 1.0 - s
        out = np.empty((len(times), 4))
        out[:, :2] = np.einsum("nk,nkd->nd", _basis(b.coef, b.powers, s, rest_s), b.cp[idx])
        if b.degree == 0:
            out[:, 2:] = 0.0
        else:
            out[:, 2:] = np.einsum("nk,nkd->nd", _basis(b.dcoef, b.dpowers, s, rest_s), b.dcp[idx])
        return out

    def positions(self, name: str, times: np.ndarray) -> np.ndarray:
        """[x, y] (m) of body ``name`` at each time, shape (len(times), 2): ``state(name, times)[:, :2]``
        without the velocities (the other robots' paths in the safe-segment limits need only these)."""
        b = self._bodies[name]
        idx, s = self._locate(b, np.asarray(times, float))
        s = s[:, None]
        return np.einsum("nk,nkd->nd", _basis(b.coef, b.powers, s, 1.0 - s), b.cp[idx])

    def position(self, name: str, t: float) -> np.ndarray:
        return self.state(name, np.array([float(t)]))[0, :2]

    def velocity(self, name: str, t: float) -> np.ndarray:
        return self.state(name, np.array([float(t)]))[0, 2:]
