"""The thesis's Eq. (5), ``x' = w * sum_i (a_i - x) / |a_i - x|``, and its classical Runge-Kutta (RK4) step.

What the ``kinematic`` fidelity moves the cargo by (:mod:`impact_env.tether.kinematic`) and the reference the
planners and tests compare paths with (:func:`eq5_rk4_path`). :func:`rk4_one` and :func:`rk4_two` are
:func:`rk4_eq5` for one and two anchors written out, the same operations in the same order (bit-identical).
"""

from __future__ import annotations

import math

import numpy as np


def eq5_velocity(x: float, y: float, anchors: list[tuple[float, float]], w: float,
                 ws: list[float] | None = None) -> tuple[float, float]:
    """Eq. (5): ``w`` times the sum of the unit vectors from (x, y) toward the anchors (m/s); with ``ws`` each
    anchor's tether reels at its own speed."""
    vx = vy = 0.0
    if ws is None:
        for ax, ay in anchors:
            dx, dy = ax - x, ay - y
            d = math.hypot(dx, dy)
            vx += dx / d
            vy += dy / d
        return w * vx, w * vy
    for (ax, ay), wi in zip(anchors, ws):
        dx, dy = ax - x, ay - y
        d = math.hypot(dx, dy)
        vx += wi * dx / d
        vy += wi * dy / d
    return vx, vy


def rk4_one(x: float, y: float, ax: float, ay: float, w: float, dt: float) -> tuple[float, float]:
    """:func:`rk4_eq5` for one anchor, written out (the same operations in the same order)."""
    dx, dy = ax - x, ay - y
    d = math.hypot(dx, dy)
    k1x, k1y = w * (0.0 + dx / d), w * (0.0 + dy / d)
    h = 0.5 * dt
    dx, dy = ax - (x + h * k1x), ay - (y + h * k1y)
    d = math.hypot(dx, dy)
    k2x, k2y = w * (0.0 + dx / d), w * (0.0 + dy / d)
    dx, dy = ax - (x + h * k2x), ay - (y + h * k2y)
    d = math.hypot(dx, dy)
    k3x, k3y = w * (0.0 + dx / d), w * (0.0 + dy / d)
    dx, dy = ax - (x + dt * k3x), ay - (y + dt * k3y)
    d = math.hypot(dx, dy)
    k4x, k4y = w * (0.0 + dx / d), w * (0.0 + dy / d)
    sixth = dt / 6.0
    return (x + sixth * (k1x + 2.0 * k2x + 2.0 * k3x + k4x), y + sixth * (k1y + 2.0 * k2y + 2.0 * k3y + k4y))


def rk4_two(x: float, y: float, ax: float, ay: float, bx: float, by: float, w: float,
            dt: float) -> tuple[float, float]:
    """:func:`rk4_eq5` for two anchors reeling at the same speed, written out (the same operations in order)."""
    h = 0.5 * dt
    dx, dy, ex, ey = ax - x, ay - y, bx - x, by - y
    d, e = math.hypot(dx, dy), math.hypot(ex, ey)
    k1x, k1y = w * (0.0 + dx / d + ex / e), w * (0.0 + dy / d + ey / e)
    px, py = x + h * k1x, y + h * k1y
    dx, dy, ex, ey = ax - px, ay - py, bx - px, by - py
    d, e = math.hypot(dx, dy), math.hypot(ex, ey)
    k2x, k2y = w * (0.0 + dx / d + ex / e), w * (0.0 + dy / d + ey / e)
    px, py = x + h * k2x, y + h * k2y
    dx, dy, ex, ey = ax - px, ay - py, bx - px, by - py
    d, e = math.hypot(dx, dy), math.hypot(ex, ey)
    k3x, k3y = w * (0.0 + dx / d + ex / e), w * (0.0 + dy / d + ey / e)
    px, py = x + dt * k3x, y + dt * k3y
    dx, dy, ex, ey = ax - px, ay - py, bx - px, by - py
    d, e = math.hypot(dx, dy), math.hypot(ex, ey)
    k4x, k4y = w * (0.0 + dx / d + ex / e), w * (0.0 + dy / d + ey / e)
    sixth = dt / 6.0
    return (x + sixth * (k1x + 2.0 * k2x + 2.0 * k3x + k4x), y + sixth * (k1y + 2.0 * k2y + 2.0 * k3y + k4y))


def rk4_eq5(x: float, y: float, anchors: list[tuple[float, float]], w: float, dt: float,
            ws: list[float] | None = None) -> tuple[float, float]:
    """One RK4 step of ``dt`` of Eq. (5) from (x, y); with ``ws`` each anchor's tether reels at its own speed."""
    k1 = eq5_velocity(x, y, anchors, w, ws)
    k2 = eq5_velocity(x + 0.5 * dt * k1[0], y + 0.5 * dt * k1[1], anchors, w, ws)
    k3 = eq5_velocity(x + 0.5 * dt * k2[0], y + 0.5 * dt * k2[1], anchors, w, ws)
    k4 = eq5_velocity(x + dt * k3[0], y + dt * k3[1], anchors, w, ws)
    return (x + dt / 6.0 * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0]),
            y + dt / 6.0 * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1]))


def eq5_rk4_path(start: tuple[float, float], anchors: list[tuple[float, float]], w: float, dt: float,
                 steps: int) -> np.ndarray:
    """(steps + 1, 2) positions of Eq. (5) from ``start`` by RK4 steps of ``dt`` (planners' and tests' reference)."""
    out = [tuple(start)]
    x, y = start
    for _ in range(steps):
        x, y = rk4_eq5(x, y, anchors, w, dt)
        out.append((x, y))
    return np.array(out)
