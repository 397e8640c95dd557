"""Closed-form feasibility of the replanner's bounded segment (its QP without the safe-segment limits).

The replanner (:mod:`planners.online.replanner`) asks for a degree-d Bezier curve over ``[t0, t0 + T]`` with
fixed end positions and velocities, whose velocity control points stay within a per-axis bound V (Eq. 25)
and whose acceleration control points stay within the thrust limit A. Without the safe-segment limits the
axes are independent and whether such a curve exists has a closed form, :func:`bounds_feasible`: per axis,
with ``m = d - 1``, ``h = A T / (d - 1)``, ``u_i = min(v0 + i h, v1 + (m - i) h, V)`` and
``l_i = max(v0 - i h, v1 - (m - i) h, -V)``, a curve exists if and only if ``|v0|, |v1| <= V`` and
``sum l <= d (p1 - p0) / T <= sum u``. :func:`least_acceleration_bound` inverts it: the least acceleration
bound that joins the end states in the time left.

A False verdict proves every QP with these end states and bounds infeasible (limits or not); ``tol`` loosens
the test by the replanner's own tolerance. The proofs: ``docs/expert_design.md#segment-feasibility``.
"""

from __future__ import annotations

import math

import numpy as np

from planners.errors import ReplanInputError

FEASIBILITY_TOL = 1e-6  # m/s and m/s^2: the tolerance of the replanner's bound check


def velocity_sum_range(v0, v1, duration_s: float, degree: int, velocity_bound=None,
                       acceleration_bound=None) -> tuple[np.ndarray, np.ndarray]:
    """Per axis, the least and the largest sum of the velocity control points that a degree-``degree`` curve
    from velocity ``v0`` to ``v1`` can have within the bounds (``sum l`` and ``sum u`` of the module
    docstring; meaningful when the end velocities keep the bounds)."""
    m = degree - 1
    low, high = [], []
    for axis in range(2):
        a, b = float(v0[axis]), float(v1[axis])
        bound = math.inf if velocity_bound is None else float(velocity_bound[axis])
        step = math.inf if acceleration_bound is None else float(acceleration_bound[axis]) * duration_s / m
        low.append(-_upper_sum(-a, -b, m, bound, step))
        high.append(_upper_sum(a, b, m, bound, step))
    return np.array(low), np.array(high)


def _upper_sum(v0: float, v1: float, m: int, bound: float, step: float) -> float:
    """sum u of one axis (sum l is ``-_upper_sum(-v0, -v1, ...)``: l of (v0, v1) is -u of (-v0, -v1)). Plain
    floats: for 8 terms a loop is faster than numpy's dispatch."""
    total = v0 + v1
    for i in range(1, m):
        total += min(v0 + i * step, v1 + (m - i) * step, bound)
    return total


def _check(duration_s: float, degree: int, velocity_bound, acceleration_bound) -> None:
    if not degree >= 3:
        raise ReplanInputError(f"degree must be >= 3 (two fixed control points at each end), got {degree}")
    if not duration_s > 0:
        raise ReplanInputError(f"duration_s must be > 0, got {duration_s}")
    for name, bound in (("velocity_bound", velocity_bound), ("acceleration_bound", acceleration_bound)):
        if bound is not None and not (bound[0] >= 0 and bound[1] >= 0):
            raise ReplanInputError(f"{name} must be >= 0 per axis (or None), got {bound}")


def bounds_feasible(p0, v0, p1, v1, duration_s: float, degree: int, velocity_bound=None,
                    acceleration_bound=None, tol: float = FEASIBILITY_TOL) -> bool:
    """True if a degree-``degree`` Bezier curve of duration ``duration_s`` s joins (p0, v0) to (p1, v1) with
    its velocity control points within ``velocity_bound`` (m/s per axis) and its acceleration control points
    within ``acceleration_bound`` (m/s^2 per axis), each loosened by ``tol``; exact (see the module
    docstring). Either bound may be None (no bound)."""
    _check(duration_s, degree, velocity_bound, acceleration_bound)
    m = degree - 1
    slack = tol * degree  # tol on each of the d velocity control points
    for axis in range(2):
        a, b = float(v0[axis]), float(v1[axis])
        bound = math.inf if velocity_bound is None else float(velocity_bound[axis]) + tol
        if not (abs(a) <= bound and abs(b) <= bound):
            return False  # (a); (b) is part of (c)
        step = math.inf if acceleration_bound is None else (float(acceleration_bound[axis]) + tol) * duration_s / m
        s = degree * (float(p1[axis]) - float(p0[axis])) / duration_s
        if not -_upper_sum(-a, -b, m, bound, step) - slack <= s <= _upper_sum(a, b, m, bound, step) + slack:
            return False
    return True


def least_acceleration_bound(p0, v0, p1, v1, duration_s: float, degree: int, velocity_bound,
                             acceleration_bound, tol: float = FEASIBILITY_TOL) -> np.ndarray | None:
    """Per axis, the least acceleration bound (m/s^2), no lower than ``acceleration_bound``, with which a
    degree-``degree`` curve of duration ``duration_s`` s joins (p0, v0) to (p1, v1) within ``velocity_bound``
    (m/s per axis, or None); None if the velocity bound alone cannot be met (then no acceleration can). Exact
    (see the module docstring); ``tol`` loosens the velocity bound as in :func:`bounds_feasible`."""
    _check(duration_s, degree, velocity_bound, acceleration_bound)
    m = degree - 1
    out = np.empty(2)
    for axis in range(2):
        a, b = float(v0[axis]), float(v1[axis])
        bound = math.inf if velocity_bound is None else float(velocity_bound[axis]) + tol
        if not (abs(a) <= bound and abs(b) <= bound):
            return None
        s = degree * (float(p1[axis]) - float(p0[axis])) / duration_s
        given = float(acceleration_bound[axis])
        step0 = given * duration_s / m
        # sum u must reach up to S, and sum l down to it: sum u of the mirrored axis up to -S
        step = max(_least_step(a, b, s, m, bound, step0), _least_step(-a, -b, -s, m, bound, step0))
        if step == math.inf:
            return None
        out[axis] = max(given, step * m / duration_s)
    return out


def _least_step(v0: float, v1: float, s: float, m: int, bound: float, step0: float) -> float:
    """The least h >= step0 with ``sum u(h) >= s`` (one axis; inf if none): a binary search over the sorted
    kinks of the nondecreasing, piecewise-linear sum u, then linear interpolation between the two kinks that
    bracket s (module docstring)."""
    value0 = _upper_sum(v0, v1, m, bound, step0)
    if value0 >= s:
        return step0
    candidates: set[float] = set()
    for i in range(1, m):
        candidates.update(((bound - v0) / i, (bound - v1) / (m - i)))
        if 2 * i != m:
            candidates.add((v1 - v0) / (2 * i - m))
    kinks = sorted(k for k in candidates if step0 < k < math.inf)
    lo, hi = 0, len(kinks)
    values: dict[int, float] = {}
    while lo < hi:  # the first kink at which sum u reaches s
        mid = (lo + hi) // 2
        values[mid] = _upper_sum(v0, v1, m, bound, kinks[mid])
        lo, hi = (lo, mid) if values[mid] >= s else (mid + 1, hi)
    start = kinks[lo - 1] if lo > 0 else step0
    start_value = (values[lo - 1] if lo - 1 in values else _upper_sum(v0, v1, m, bound, start)) if lo > 0 \
        else value0
    if lo == len(kinks):  # past the last kink every term is on its final piece: V, or the slope min(i, m - i)
        slope = 0.0 if bound < math.inf else float(sum(min(i, m - i) for i in range(1, m)))
        return start + (s - start_value) / slope if slope > 0 else math.inf
    end = kinks[lo]
    return start + (s - start_value) * (end - start) / (values[lo] - start_value)


__all__ = ["FEASIBILITY_TOL", "bounds_feasible", "least_acceleration_bound", "velocity_sum_range"]
