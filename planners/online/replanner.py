"""The online two-body replanner (paper Eq. 29): re-solve a robot's pre- and post-impact segments.

When a robot is on its pre-impact segment and its object flies freely toward the planned impact, the
replanner takes the robot's current state, the contact it must make (from the circular impact model,
:func:`planners.online.impact_model.required_contact`: contact position, pre- and post-impact velocities) and
the point where it rejoins the offline plan, and returns two segments:

    pre:  (p_now, v_now) at t_now      -> (p_contact, v_before) at t_impact
    post: (p_contact, v_after) at t_impact -> (p_rejoin, v_rejoin) at t_rejoin

each minimising the integral of |r''|^2 (Eq. 29's acceleration cost; the contact state is imposed exactly
rather than through Eq. 29c-d's penalties, since the closed-form impact inverse is exact). Without bounds
the minimiser is the cubic Hermite curve (closed form, microseconds); if that breaks the velocity bounds,
the convex QP over degree-10 Bezier control points with the bounds (Eq. 25) is solved with HiGHS
(a high degree because bounding the velocity control points is conservative: the hull tightens with it).
"""

from __future__ import annotations

import numpy as np

from planners.offline.milp.model import LinExpr, Model
from planners.offline.solvers import solve
from planners.offline.solvers.base import SolverOptions, Status
from planners.plan import Segment


def hermite(p0, v0, p1, v1, t0: float, t1: float) -> Segment:
    """Cubic Bezier with the given end positions and velocities: the minimum of the integral of |r''|^2."""
    p0, v0, p1, v1 = (np.asarray(a, float) for a in (p0, v0, p1, v1))
    T = t1 - t0
    return Segment(t0, t1, np.array([p0, p0 + v0 * T / 3.0, p1 - v1 * T / 3.0, p1]))


def within_bounds(segment: Segment, velocity_bound) -> bool:
    if velocity_bound is None:
        return True
    return bool(np.all(np.abs(segment.velocity_control_points()) <= np.asarray(velocity_bound) + 1e-9))


def bounded_segment(p0, v0, p1, v1, t0: float, t1: float, velocity_bound, degree: int = 10) -> Segment | None:
    """The convex QP: min integral |r''|^2 over degree-``degree`` Bezier control points, end states fixed,
    velocity control points within the per-axis bound. None if infeasible (bounds too tight for the move).
    """
    T = t1 - t0
    m = Model(name="replan")
    cp = [(m.add_var(), m.add_var()) for _ in range(degree + 1)]
    for axis in range(2):
        m.add(cp[0][axis] == float(p0[axis]), group="start")
        m.add(cp[-1][axis] == float(p1[axis]), group="end")
        m.add((cp[1][axis] - cp[0][axis]) * (degree / T) == float(v0[axis]), group="start")
        m.add((cp[-1][axis] - cp[-2][axis]) * (degree / T) == float(v1[axis]), group="end")
        for i in range(degree):
            v = (cp[i + 1][axis] - cp[i][axis]) * (degree / T)
            m.add([v <= float(velocity_bound[axis]), v >= -float(velocity_bound[axis])], group="velocity bounds")
    m.set_objective(LinExpr(), maximize=False)
    # integral of |r''|^2 over the segment, up to a constant factor, by the squared second differences
    c = degree * (degree - 1) / T ** 2
    for i in range(degree - 1):
        for axis in range(2):
            m.add_quadratic((cp[i + 2][axis] - cp[i + 1][axis] * 2.0 + cp[i][axis]) * c)
    result = solve(m, "highs", SolverOptions(time_limit_s=0.5))
    if result.status != Status.OPTIMAL:
        return None
    x = result.x
    return Segment(t0, t1, np.array([[p[0].value(x), p[1].value(x)] for p in cp]))


def replan_segment(p0, v0, p1, v1, t0: float, t1: float, velocity_bound=None) -> Segment:
    """Closed form if it respects the bounds, else the bounded QP, else (bounds unreachable) the closed form."""
    segment = hermite(p0, v0, p1, v1, t0, t1)
    if within_bounds(segment, velocity_bound):
        return segment
    return bounded_segment(p0, v0, p1, v1, t0, t1, velocity_bound) or segment


def replan_around_impact(t_now: float, position, velocity, t_impact: float, contact, t_rejoin: float,
                         rejoin_position, rejoin_velocity, velocity_bound=None) -> tuple[Segment, Segment]:
    """The robot's new pre- and post-impact segments (see the module docstring)."""
    if not t_now < t_impact < t_rejoin:
        raise ValueError(f"need t_now < t_impact < t_rejoin, got {t_now}, {t_impact}, {t_rejoin}")
    pre = replan_segment(position, velocity, contact.robot_position, contact.robot_velocity_before, t_now, t_impact,
                         velocity_bound)
    post = replan_segment(contact.robot_position, contact.robot_velocity_after, rejoin_position, rejoin_velocity,
                          t_impact, t_rejoin, velocity_bound)
    return pre, post
