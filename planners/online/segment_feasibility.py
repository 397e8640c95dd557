"""Closed-form feasibility of the replanner's bounded segment (its QP without the safe-segment limits).

The replanner (:mod:`planners.online.replanner`) asks for a degree-d Bezier curve over ``[t0, t0 + T]`` with
fixed end positions and velocities (the first two and last two control points, Eq. 8 at s = 0 and 1) whose
velocity control points stay within a per-axis velocity bound (Eq. 25) and whose acceleration control points
stay within the thrust limit. Without the safe-segment limits (box, obstacle faces, other robots) the two axes
are independent, and whether such a curve exists has a closed form, :func:`bounds_feasible`.

**The test (one axis).** Write the velocity control points ``w_i = d (P_{i+1} - P_i) / T``, i = 0..d-1, and
``m = d - 1``. The acceleration control points are ``(d - 1) (w_{i+1} - w_i) / T``, so the QP's constraints
are exactly:

- ``w_0 = v0`` and ``w_m = v1`` (the fixed second and second-to-last control points, given the end positions);
- ``sum_i w_i = S := d (p1 - p0) / T`` (the curve ends at p1, given that it starts at p0);
- ``|w_i| <= V`` (the velocity bound) and ``|w_{i+1} - w_i| <= h := A T / (d - 1)`` (the acceleration bound A).

The map from the control points (P_0 fixed) to w is one to one, so the QP is feasible if and only if such a w
exists. Let ``u_i = min(v0 + i h, v1 + (m - i) h, V)`` and ``l_i = max(v0 - i h, v1 - (m - i) h, -V)``.

*Claim:* a w exists if and only if (a) ``|v0| <= V`` and ``|v1| <= V``, (b) ``|v1 - v0| <= m h``, and
(c) ``sum_i l_i <= S <= sum_i u_i``; and (c) implies (b), so the test checks (a) and (c).

*Necessary:* (a) and (b) are constraints themselves (b: m steps of at most h each lead from v0 to v1). Any
feasible w has ``w_i <= v0 + i h`` (i steps from w_0), ``w_i <= v1 + (m - i) h`` (m - i steps to w_m) and
``w_i <= V``, so ``w_i <= u_i`` and ``sum w <= sum u``; likewise ``sum w >= sum l``. (c) implies (b): if
``v1 - v0 > m h``, then at every interior i (there is one, as d >= 3) ``u_i <= v0 + i h < v1 - (m - i) h
<= l_i``, so ``sum l > sum u`` (the ends add v0 + v1 to both); likewise if ``v0 - v1 > m h``.

*Sufficient:* u is itself feasible under (a) and (b): ``u_0 = min(v0, v1 + m h, V) = v0`` and ``u_m = v1``;
each of the three sequences changes by at most h per step and so does their pointwise minimum; ``u_i <= V``
by construction and ``u_i >= -V`` because each term is (``v0 + i h >= v0 >= -V``, the same for v1). So is l.
The constraints are convex, so ``(1 - c) l + c u`` is feasible for every c in [0, 1]; its sum moves
continuously from ``sum l`` to ``sum u`` and takes every value S in between. Without a velocity bound V is
infinite, without an acceleration bound h is (then u is v0, V, ..., V, v1).

**Use.** The QP with the limits has more constraints, so this test is necessary for it too: a False verdict
proves every QP with these end states and bounds infeasible (limits or not), a True one proves the QP without
limits feasible. ``tol`` loosens the test (bounds and S) by the tolerance the replanner accepts an answer with,
so it never rules out a segment the replanner would accept, whatever the rounding.

**The least acceleration bound** (:func:`least_acceleration_bound`). When the thrust cannot join the end
states in the time left, the replanner raises the acceleration bound of the axes that need it to the least
value that can. Each term of ``u_i`` is nondecreasing in h and each of ``l_i`` nonincreasing, so ``sum u`` is
nondecreasing and ``sum l`` nonincreasing in h, and the h that pass (c) form a ray ``[h*, inf)`` (or none: with
a velocity bound, ``sum u`` stops growing once every u_i is V). Both sums are piecewise linear in h, with
kinks only where two terms of a min (max) are equal: ``h = (V - v0) / i`` and ``(V - v1) / (m - i)`` for
u, ``(V + v0) / i`` and ``(V + v1) / (m - i)`` for l, and where the two slopes cross,
``(v1 - v0) / (2 i - m)``, for both. Evaluated at those kinks, each sum is inverted exactly by linear
interpolation between the two kinks that bracket S; past the last kink every term is on its final piece (V,
or without a velocity bound the one of slope ``min(i, m - i)``), so the sums continue with a known slope.
"""

from __future__ import annotations

import numpy as np

from planners.errors import ReplanInputError

FEASIBILITY_TOL = 1e-6  # m/s and m/s^2: the tolerance of the replanner's bound check


def velocity_sum_range(v0, v1, duration_s: float, degree: int, velocity_bound=None,
                       acceleration_bound=None) -> tuple[np.ndarray, np.ndarray]:
    """Per axis, the least and the largest sum of the velocity control points that a degree-``degree`` curve
    from velocity ``v0`` to ``v1`` can have within the bounds (``sum l`` and ``sum u`` of the module
    docstring; meaningful when the end velocities keep the bounds)."""
    v0, v1 = np.asarray(v0, float), np.asarray(v1, float)
    m = degree - 1
    bound = np.full(2, np.inf) if velocity_bound is None else np.asarray(velocity_bound, float)
    interior = np.arange(1, m, dtype=float)[:, None]  # the ends are v0 and v1 themselves
    if acceleration_bound is None:
        upper = np.broadcast_to(bound, (m - 1, 2))
        lower = -upper
    else:
        h = np.asarray(acceleration_bound, float) * duration_s / m
        upper = np.minimum(np.minimum(v0 + interior * h, v1 + (m - interior) * h), bound)
        lower = np.maximum(np.maximum(v0 - interior * h, v1 - (m - interior) * h), -bound)
    return v0 + v1 + lower.sum(axis=0), v0 + v1 + upper.sum(axis=0)


def _check(duration_s: float, degree: int, velocity_bound, acceleration_bound) -> None:
    if not degree >= 3:
        raise ReplanInputError(f"degree must be >= 3 (two fixed control points at each end), got {degree}")
    if not duration_s > 0:
        raise ReplanInputError(f"duration_s must be > 0, got {duration_s}")
    for name, bound in (("velocity_bound", velocity_bound), ("acceleration_bound", acceleration_bound)):
        if bound is not None and not (np.asarray(bound, float) >= 0).all():
            raise ReplanInputError(f"{name} must be >= 0 per axis (or None), got {bound}")


def bounds_feasible(p0, v0, p1, v1, duration_s: float, degree: int, velocity_bound=None,
                    acceleration_bound=None, tol: float = FEASIBILITY_TOL) -> bool:
    """True if a degree-``degree`` Bezier curve of duration ``duration_s`` s joins (p0, v0) to (p1, v1) with
    its velocity control points within ``velocity_bound`` (m/s per axis) and its acceleration control points
    within ``acceleration_bound`` (m/s^2 per axis), each loosened by ``tol``; exact (see the module
    docstring). Either bound may be None (no bound)."""
    _check(duration_s, degree, velocity_bound, acceleration_bound)
    v0, v1 = np.asarray(v0, float), np.asarray(v1, float)
    velocity_bound = None if velocity_bound is None else np.asarray(velocity_bound, float) + tol
    if acceleration_bound is not None:
        acceleration_bound = np.asarray(acceleration_bound, float) + tol
    if velocity_bound is not None and ((np.abs(v0) > velocity_bound) | (np.abs(v1) > velocity_bound)).any():
        return False  # (a); (b) is part of (c)
    low, high = velocity_sum_range(v0, v1, duration_s, degree, velocity_bound, acceleration_bound)
    s = degree * (np.asarray(p1, float) - np.asarray(p0, float)) / duration_s
    slack = tol * degree  # tol on each of the d velocity control points
    return bool(((low - slack <= s) & (s <= high + slack)).all())


def least_acceleration_bound(p0, v0, p1, v1, duration_s: float, degree: int, velocity_bound,
                             acceleration_bound, tol: float = FEASIBILITY_TOL) -> np.ndarray | None:
    """Per axis, the least acceleration bound (m/s^2), no lower than ``acceleration_bound``, with which a
    degree-``degree`` curve of duration ``duration_s`` s joins (p0, v0) to (p1, v1) within ``velocity_bound``
    (m/s per axis, or None); None if the velocity bound alone cannot be met (then no acceleration can). Exact
    (see the module docstring); ``tol`` loosens the velocity bound as in :func:`bounds_feasible`."""
    _check(duration_s, degree, velocity_bound, acceleration_bound)
    v0, v1 = np.asarray(v0, float), np.asarray(v1, float)
    bound = np.full(2, np.inf) if velocity_bound is None else np.asarray(velocity_bound, float) + tol
    if ((np.abs(v0) > bound) | (np.abs(v1) > bound)).any():
        return None
    m = degree - 1
    s = degree * (np.asarray(p1, float) - np.asarray(p0, float)) / duration_s
    out = np.array(acceleration_bound, dtype=float)
    for axis in range(2):
        step = _least_step(v0[axis], v1[axis], s[axis], m, bound[axis], out[axis] * duration_s / m)
        if not np.isfinite(step):
            return None
        out[axis] = max(out[axis], step * m / duration_s)
    return out


def _least_step(v0: float, v1: float, s: float, m: int, bound: float, step0: float) -> float:
    """The least h >= step0 with ``sum l(h) <= s <= sum u(h)`` (one axis; inf if none)."""
    i = np.arange(1, m, dtype=float)
    j = m - i
    with np.errstate(divide="ignore", invalid="ignore"):
        # (v0 - v1) / (2 i - m) is the same set as (v1 - v0) / (2 i - m): i and m - i swap
        kinks = np.concatenate([(bound - v0) / i, (bound + v0) / i, (bound - v1) / j, (bound + v1) / j,
                                (v1 - v0) / (2 * i - m)])
    kinks = kinks[np.isfinite(kinks) & (kinks > step0)]
    h = np.unique(np.concatenate([[step0], kinks]))
    upper = v0 + v1 + np.minimum(np.minimum(v0 + np.outer(h, i), v1 + np.outer(h, j)), bound).sum(axis=1)
    lower = v0 + v1 + np.maximum(np.maximum(v0 - np.outer(h, i), v1 - np.outer(h, j)), -bound).sum(axis=1)
    # past the last kink every term is on its final piece: V (slope 0) with a velocity bound, else the
    # smaller of the two slopes i and m - i
    ray = 0.0 if np.isfinite(bound) else float(np.minimum(i, j).sum())
    return max(_least_reaching(h, upper, s, ray), _least_reaching(h, -lower, -s, ray))


def _least_reaching(h: np.ndarray, values: np.ndarray, target: float, ray_slope: float) -> float:
    """The least x >= h[0] at which the nondecreasing piecewise-linear function through (h, values), continued
    with slope ``ray_slope`` past h[-1], reaches ``target`` (inf if it never does)."""
    reached = values >= target
    if reached[0]:
        return float(h[0])
    if not reached.any():
        return float(h[-1] + (target - values[-1]) / ray_slope) if ray_slope > 0 else np.inf
    k = int(np.argmax(reached))
    return float(h[k - 1] + (target - values[k - 1]) * (h[k] - h[k - 1]) / (values[k] - values[k - 1]))


__all__ = ["FEASIBILITY_TOL", "bounds_feasible", "least_acceleration_bound", "velocity_sum_range"]
