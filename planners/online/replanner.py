"""The online two-body replanner (paper Eq. 29): re-solve a robot's pre- and post-impact segments.

From the robot's current state, the contact it must make (position, pre- and post-impact velocities, from
the disc law's inverse in :mod:`planners.online.impact_model`) and the point where it rejoins the offline
plan, it returns two segments:

    pre:  (p_now, v_now) at t_now      -> (p_contact, v_before) at t_impact
    post: (p_contact, v_after) at t_impact -> (p_rejoin, v_rejoin) at t_rejoin

each minimising the integral of |r''|^2 with the contact state imposed exactly. Without bounds the minimiser
is the cubic Hermite curve (closed form); when that breaks a bound, the bounded QP of
:mod:`planners.online.segment_qp` (``SegmentLimits``, ``bounded_segment`` and ``hermite``, importable from
here too) is solved, unless the closed forms of :mod:`planners.online.segment_feasibility` prove it
infeasible. Why the bounds, with the measurements: ``docs/expert_design.md#replanner``.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from planners import bezier
from planners.errors import ReplanInputError
from planners.online.segment_feasibility import FEASIBILITY_TOL, bounds_feasible, least_acceleration_bound
from planners.online.segment_qp import DEGREE, SegmentLimits, WayRound, bounded_segment, hermite, separation_rows
from planners.plan import Segment

# a raised acceleration bound is this much (relative) above the least one: at the least one the QP's feasible set
# can be a single point
RAISED_MARGIN = 1e-3


def within_bounds(segment: Segment, velocity_bound, acceleration_bound=None) -> bool:
    """Velocity (and acceleration) control points within the per-axis bounds: the hull bounds the curve."""
    cp = segment.control_points
    d = len(cp) - 1
    if d == 0:
        return velocity_bound is None or bool((0.0 <= np.asarray(velocity_bound) + 1e-9).all())
    # the control points of Segment.velocity_control_points / acceleration_control_points, computed alike
    # (a[1:] - a[:-1] is np.diff without its argument handling: the same numbers)
    first = d * (cp[1:] - cp[:-1])
    if velocity_bound is not None and \
            not (np.abs(first / segment.duration_s) <= np.asarray(velocity_bound) + 1e-9).all():
        return False
    if acceleration_bound is not None and d > 1 and \
            not (np.abs((d - 1) * (first[1:] - first[:-1]) / segment.duration_s ** 2)
                 <= np.asarray(acceleration_bound) + 1e-9).all():
        return False
    return True


def respects(segment: Segment, velocity_bound, limits: SegmentLimits | None, tol: float = 1e-7,
             acceleration_bound=None) -> bool:
    """True if the segment keeps its velocity (and acceleration) bound and the limits (on its control points
    and separation samples)."""
    if not within_bounds(segment, velocity_bound, acceleration_bound):
        return False
    if limits is None:
        return True
    cp = segment.control_points
    if limits.box is not None:
        x0, x1, y0, y1 = limits.box
        (xlo, ylo), (xhi, yhi) = cp.min(axis=0), cp.max(axis=0)
        if xlo < x0 - tol or xhi > x1 + tol or ylo < y0 - tol or yhi > y1 + tol:
            return False
    for n, b in limits.half_planes:
        if (cp @ n).min() < b - tol:
            return False
    rows = separation_rows(segment, limits)
    if not rows:
        return True
    phases = np.array([r[0] for r in rows])
    points = bezier.evaluate(segment.control_points, phases)
    return all(n @ p >= b - tol for (_, n, b), p in zip(rows, points))


def replan_segment(p0, v0, p1, v1, t0: float, t1: float, velocity_bound=None,
                   limits: SegmentLimits | None = None, acceleration_bound=None) -> Segment:
    """The cheapest segment that meets what can be met, in this order of giving up:

    the closed form if it respects everything; else the QP with every bound and limit; else without the way
    round (:class:`~planners.online.segment_qp.WayRound`, if the limits have one); else without the
    limits (the MPC's keep-offs still guard walls and robots) but flyable (acceleration bound); else with the
    velocity bound alone (the paper's replanner); else the closed form. If no flyable segment exists, the
    acceleration bound of those QPs is the least that can be met (below).

    The end states are never given up: every answer starts at (p0, v0) and ends at (p1, v1) (a QP answer
    that does not is no answer, see :meth:`planners.online.segment_qp._SegmentQP.answer_holds`). When no
    flyable segment joins them (the robot is too far from the contact, or too fast, for the thrust it has in
    the time left), which the closed-form test :func:`~planners.online.segment_feasibility.bounds_feasible`
    tells before any QP is solved, the acceleration bound of the axes that need it is raised to the least
    that can (:func:`~planners.online.segment_feasibility.least_acceleration_bound`, plus ``RAISED_MARGIN``):
    the segment then asks for as little thrust beyond the robot's as the contact allows, and the MPC's thrust
    limits decide how close the robot gets; the approach is replanned from the new state at the next step.
    Only if the velocity bound cannot be met either (the robot or the contact faster than the bound) does
    the closed form remain."""
    segment = hermite(p0, v0, p1, v1, t0, t1)
    if respects(segment, velocity_bound, limits, acceleration_bound=acceleration_bound):
        return segment
    T = t1 - t0
    acc = acceleration_bound
    if not bounds_feasible(p0, v0, p1, v1, T, DEGREE, velocity_bound, acc):
        least = None if acc is None else least_acceleration_bound(p0, v0, p1, v1, T, DEGREE, velocity_bound, acc)
        if least is None:  # not even the velocity bound can be kept
            return segment
        acc = np.where(least > acc, least * (1.0 + RAISED_MARGIN) + FEASIBILITY_TOL, acc)
    attempts: list[tuple[SegmentLimits | None, Any]] = [(limits, acc)] if limits is not None else []
    if limits is not None and limits.way_round is not None:
        # the way round is given up before the other limits: without it the segment is the one it was before
        attempts.append((dataclasses.replace(limits, way_round=None), acc))
    if acc is not None:
        attempts.append((None, acc))
    for lim, bound in attempts:
        # the separation rows are linearised about the closed form: ``segment`` is that curve, made once
        qp = bounded_segment(p0, v0, p1, v1, t0, t1, velocity_bound, limits=lim, around=segment,
                             acceleration_bound=bound)
        if qp is not None:
            return qp
    if within_bounds(segment, velocity_bound):
        return segment
    return bounded_segment(p0, v0, p1, v1, t0, t1, velocity_bound) or segment


def replan_around_impact(t_now: float, position, velocity, t_impact: float, contact, t_rejoin: float,
                         rejoin_position, rejoin_velocity, velocity_bound=None,
                         limits: SegmentLimits | None = None, acceleration_bound=None,
                         way_round: WayRound | None = None) -> tuple[Segment, Segment]:
    """The robot's new pre- and post-impact segments (see the module docstring). ``way_round``: the object the
    pre-impact segment must get round to its contact (:class:`~planners.online.segment_qp.WayRound`), added to
    that segment's limits only."""
    if not t_now < t_impact < t_rejoin:
        raise ReplanInputError(f"need t_now < t_impact < t_rejoin, got {t_now}, {t_impact}, {t_rejoin}")
    pre_limits = limits if way_round is None else dataclasses.replace(limits or SegmentLimits(), way_round=way_round)
    pre = replan_segment(position, velocity, contact.robot_position, contact.robot_velocity_before, t_now, t_impact,
                         velocity_bound, pre_limits, acceleration_bound)
    post = replan_segment(contact.robot_position, contact.robot_velocity_after, rejoin_position, rejoin_velocity,
                          t_impact, t_rejoin, velocity_bound, limits, acceleration_bound)
    return pre, post


def obstacle_half_planes(obstacles, position, radius_m: float, reach_m: float) -> list[tuple[np.ndarray, float]]:
    """For each convex obstacle within ``reach_m`` of ``position``: the half-plane of the face the centre is
    most beyond, shifted out by the radius (``normal . p >= offset + radius``)."""
    out = []
    p = np.asarray(position, float)
    for poly in obstacles:
        dist = poly.normals @ p - poly.offsets
        face = int(np.argmax(dist))
        if dist[face] < reach_m + radius_m:
            out.append((poly.normals[face].copy(), float(poly.offsets[face]) + radius_m))
    return out


def distance_to_box(position, box) -> float:
    x, y = position
    return min(x - box[0], box[1] - x, y - box[2], box[3] - y)


__all__ = ["SegmentLimits", "WayRound", "bounded_segment", "distance_to_box", "hermite", "obstacle_half_planes",
           "replan_around_impact", "replan_segment", "respects", "within_bounds"]
