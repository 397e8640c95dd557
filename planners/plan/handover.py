"""Hand-overs: a robot that hits one object twice in a row from opposite sides must get round it in between.

The planners' bodies are points, so a plan can have a robot push an object from behind and then stop it from
the front: the point robot flies through the object. A disc robot has to get round it, in the object's frame
(inertial while nothing else hits the object) from its contact at the first impact to its contact at the
second, outside the disc of radius r_R + r_O. :func:`least_time_round_s` is a lower bound of the time that
takes at the robot's thrust limit (and within its speed bound): the largest of relaxations, each exact for a
one-dimensional double integrator with the box of body-frame thrusts and per-axis speeds projected on it:

- along any direction the robot must move from its first contact to its second, starting and ending with
  its relative velocities (the bound takes the largest over a fan of directions, the normals and the axes);
- on the way round it must cross the ray through the middle of the arc it goes round, at least d out.

This is the one definition of a flyable hand-over: the offline planners refuse or repair a plan whose
hand-over has less than ``1 + margin`` times the least time (:class:`planners.offline.config.HandoverConfig`),
and the mission layer refuses a re-plan on the same test with the same margin
(:mod:`planners.online.side_switch`). Derivation: ``docs/planner_design.md#hand-overs``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from impact_env.transport.scenario import Body, Scenario
from planners.impact_law import mass_fractions
from planners.plan.types import PlanLike, PlannedImpact

__all__ = ["DIRECTIONS", "Handover", "handovers", "least_handover_time_s", "least_time_1d_s", "least_time_round_s",
           "unflyable_handovers", "contact_relative_velocity", "unit_change", "time_suffices", "needed_text",
           "PairModel"]

_EPS = 1e-9

PairModel = Callable[[str, str], tuple[float, tuple[float, float]]]
"""``model(robot, object)`` -> (restitution, (m_robot, m_object)): a pair's impact law (as the expert's contact
inverse uses it)."""


@dataclass
class Handover:
    """Two consecutive impacts of ``robot`` on ``object`` (nothing else hits the object in between) whose
    velocity changes are more than 90 degrees apart, so the robot must get round the object.

    ``needed_s``: the least time getting round takes (:func:`least_handover_time_s`; inf if the object is
    faster than the robot can be); ``available_s``: the time between the impacts, or from ``from_s`` when
    the robot is already on its way round (the mission's check from an observed state, ``needed_s`` then
    from there); ``first``, ``second``: the two impacts."""

    robot: str
    object: str
    t1_s: float
    t2_s: float
    angle_rad: float
    needed_s: float
    from_s: float | None = None
    first: PlannedImpact | None = field(default=None, repr=False, compare=False)
    second: PlannedImpact | None = field(default=None, repr=False, compare=False)

    @property
    def available_s(self) -> float:
        return self.t2_s - (self.t1_s if self.from_s is None else self.from_s)

    def flyable(self, margin: float) -> bool:
        """True if the time there is is at least ``1 + margin`` times the least time (the one margin
        convention of the offline planners and the mission layer, :class:`HandoverConfig.margin`)."""
        return time_suffices(self.available_s, self.needed_s, margin)

    def describe(self, margin: float | None = None) -> str:
        need = needed_text(self.needed_s, margin)
        return (f"{self.robot} round {self.object} between its impacts at {self.t1_s:.2f} s and {self.t2_s:.2f} s "
                f"({math.degrees(self.angle_rad):.0f} degrees apart): {need}, has {self.available_s:.2f} s"
                + ("" if self.from_s is None else f" from {self.from_s:.2f} s"))

    def to_dict(self) -> dict:
        """For ``plan.stats`` (finite numbers only: an infinite least time is None)."""
        out = {"robot": self.robot, "object": self.object, "t1_s": self.t1_s, "t2_s": self.t2_s,
               "angle_deg": math.degrees(self.angle_rad),
               "needed_s": None if math.isinf(self.needed_s) else self.needed_s, "available_s": self.available_s}
        return out if self.from_s is None else out | {"from_s": self.from_s}


def time_suffices(available_s: float, needed_s: float, margin: float) -> bool:
    """True if ``available_s`` is at least ``1 + margin`` times the least time ``needed_s`` (a way round's test:
    a hand-over's, an approach's)."""
    return available_s >= (1.0 + margin) * needed_s - 1e-9


def needed_text(needed_s: float, margin: float | None = None) -> str:
    """How a way round's least time reads in a message, with its margin when given."""
    if math.isinf(needed_s):
        return "can never get round (the object is faster than it can be)"
    return f"needs at least {needed_s:.2f} s" + (f" ({(1 + margin) * needed_s:.2f} s with the "
                                                 f"{100 * margin:g} % margin)" if margin else "")


def _unit(v: np.ndarray) -> np.ndarray | None:
    size = float(np.linalg.norm(v))
    return None if size <= 1e-6 else v / size


def unit_change(impact: PlannedImpact) -> np.ndarray | None:
    """The impact's contact normal: the direction of the object's velocity change (Eq. 6-7); None if the
    object's velocity hardly changes."""
    return _unit(np.subtract(impact.object_velocity_after, impact.object_velocity_before))


def handovers(plan: PlanLike, scenario: Scenario, model: PairModel | None = None) -> list[Handover]:
    """The plan's hand-overs (see :class:`Handover`), in time order, with their least times: the robot's
    relative velocities at the contacts are the plan's, or with ``model`` the disc law's inverse (Eq. 6-7) of
    the planned object velocities with the model's restitution and masses (the same for the file's)."""
    out = []
    ordered = sorted(plan.impacts, key=lambda i: i.time_s)
    for j, first in enumerate(ordered):
        # the robot's next impact, and the object's
        nxt_robot = next((i for i in ordered[j + 1:] if i.robot == first.robot), None)
        nxt_object = next((i for i in ordered[j + 1:] if i.object == first.object), None)
        if nxt_robot is None or nxt_robot is not nxt_object:
            continue
        second = nxt_robot
        n1, n2 = unit_change(first), unit_change(second)
        if n1 is None or n2 is None or float(n1 @ n2) >= 0.0:
            continue
        robot, obj = scenario.body(first.robot), scenario.body(first.object)
        law = None if model is None else model(first.robot, first.object)
        out.append(Handover(first.robot, first.object, first.time_s, second.time_s,
                            math.acos(float(np.clip(n1 @ n2, -1.0, 1.0))),
                            least_handover_time_s(robot, obj, first, second, law), first=first, second=second))
    return out


def unflyable_handovers(plan: PlanLike, scenario: Scenario, margin: float) -> list[Handover]:
    """The hand-overs with less than ``1 + margin`` times their least time."""
    return [h for h in handovers(plan, scenario) if not h.flyable(margin)]


def least_handover_time_s(robot: Body, obj: Body, first: PlannedImpact, second: PlannedImpact,
                          law: tuple[float, tuple[float, float]] | None = None) -> float:
    """A lower bound of the time ``robot`` needs from its contact at impact ``first`` to its contact at
    ``second`` on ``obj``, going round the object's disc (module docstring). The contact normal of an impact
    is the direction of the object's velocity change (Eq. 6-7); the robot's velocities are the plan's, or with
    ``law`` = (restitution, (m_robot, m_object)) those the disc law needs (:func:`contact_relative_velocity`)."""
    d = robot.radius_m + obj.radius_m
    n1, n2 = unit_change(first), unit_change(second)
    if n1 is None or n2 is None:
        return 0.0
    if law is None:
        u1 = np.subtract(first.robot_velocity_after, first.object_velocity_after)  # relative, after the first
        u2 = np.subtract(second.robot_velocity_before, second.object_velocity_before)  # and before the second
    else:
        u1 = contact_relative_velocity(first.object_velocity_before, first.object_velocity_after, *law)[1]
        u2 = contact_relative_velocity(second.object_velocity_before, second.object_velocity_after, *law)[0]
    return least_time_round_s(robot, first.object_velocity_after, d, -d * n1, u1, -d * n2, u2)


def contact_relative_velocity(object_velocity_before, object_velocity_after, restitution: float,
                              masses: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """The robot's velocity relative to the object (m/s) just before and just after the disc impact that changes
    the object's velocity as given: along the change's direction n, ``|change| / m3`` before and ``-e`` times
    that after (Eq. 5 along the normal: the relative normal velocity is reversed and scaled by e), none across
    it (the contact inverse keeps the robot's tangential velocity equal to the object's)."""
    change = np.subtract(object_velocity_after, object_velocity_before).astype(float)
    m3 = mass_fractions(masses[0], masses[1], restitution)[2]
    before = change / m3
    return before, -restitution * before


def least_time_round_s(robot: Body, object_velocity_mps, distance_m: float, r0, u0, r1, u1) -> float:
    """A lower bound of the time (s) ``robot`` needs, in the frame of an object moving at ``object_velocity_mps``,
    from relative position ``r0`` (m) and velocity ``u0`` (m/s) to ``r1`` and ``u1``, staying outside the disc of
    radius ``distance_m`` (r_R + r_O) round the object: the largest of the relaxations of the module docstring.

    The projection on any direction is a relaxation; the bound is the largest over :data:`DIRECTIONS` (and the
    two contact normals and the axes of the thrust box): an oblique normal alone gives the speed box's
    diagonal support, far too generous (a 160 degree hand-over of ``two_objects``: 5.7 s by the first normal,
    8.1 s along x, which a discretised trajectory round the disc matches)."""
    v_obj = np.asarray(object_velocity_mps, dtype=float)
    r0, u0, r1, u1 = (np.asarray(v, dtype=float) for v in (r0, u0, r1, u1))
    along = 0.0
    for n in _directions(robot, r0, r1):
        along = max(along, _projected_bvp_s(robot, v_obj, n, float(r0 @ n), float(u0 @ n), float(r1 @ n),
                                            float(u1 @ n)))
        if math.isinf(along):
            return along
    a0, a1 = math.atan2(float(r0[1]), float(r0[0])), math.atan2(float(r1[1]), float(r1[0]))
    angle = math.remainder(a1 - a0, 2 * math.pi)  # from r0 to r1, in [-pi, pi]
    side = math.inf
    for arc in (angle, angle - math.copysign(2 * math.pi, angle)):  # round the short side, then the long one
        # a path round the disc crosses the ray through the middle of its arc at least distance_m out:
        # it reaches m . r >= d from (r0, u0), and (backwards in time) from (r1, u1), any velocity in between
        mid = np.array([math.cos(a0 + arc / 2), math.sin(a0 + arc / 2)])
        out_s = _projected_reach_s(robot, v_obj, mid, float(r0 @ mid), float(u0 @ mid), distance_m)
        back_s = _projected_reach_s(robot, -v_obj, mid, float(r1 @ mid), -float(u1 @ mid), distance_m)
        side = min(side, out_s + back_s)
    return float(max(along, side))


DIRECTIONS = 36
"""Directions (evenly spread over half a turn) on which :func:`least_time_round_s` projects the way round."""


def _directions(robot: Body, r0: np.ndarray, r1: np.ndarray) -> list[np.ndarray]:
    c, s = math.cos(robot.heading_rad), math.sin(robot.heading_rad)
    out = [np.array([math.cos(k * math.pi / DIRECTIONS), math.sin(k * math.pi / DIRECTIONS)])
           for k in range(DIRECTIONS)] + [np.array([c, s]), np.array([-s, c])]
    out += [u for u in (_unit(r0), _unit(r1)) if u is not None]
    return out


def _limits(robot: Body, v_obj: np.ndarray, n: np.ndarray) -> tuple[float, float, float]:
    """Along unit direction n: the largest acceleration (m/s^2, the box of body-frame thrusts at the robot's
    heading) and the range of the robot's velocity relative to the object (m/s, from the per-axis speed
    bound; unbounded without one)."""
    c, s = math.cos(robot.heading_rad), math.sin(robot.heading_rad)
    fx, fy, _ = robot.wrench_limits
    accel = (fx * abs(n[0] * c + n[1] * s) + fy * abs(-n[0] * s + n[1] * c)) / robot.mass_kg
    if robot.velocity_bound_mps is None:
        return accel, -math.inf, math.inf
    speed = robot.velocity_bound_mps[0] * abs(n[0]) + robot.velocity_bound_mps[1] * abs(n[1])
    v_n = float(v_obj @ n)
    return accel, -speed - v_n, speed - v_n


def _projected_bvp_s(robot: Body, v_obj: np.ndarray, n: np.ndarray, x0: float, w0: float, x1: float,
                     w1: float) -> float:
    accel, low, high = _limits(robot, v_obj, n)
    return least_time_1d_s(x1 - x0, w0, w1, accel, low, high)


def _projected_reach_s(robot: Body, v_obj: np.ndarray, n: np.ndarray, x0: float, w0: float, target: float) -> float:
    """The least time from (x0, w0) to x >= target along n, any end velocity (full thrust toward it)."""
    accel, _, high = _limits(robot, v_obj, n)
    gap = target - x0
    if gap <= 0.0:
        return 0.0
    if accel <= _EPS:
        return math.inf if w0 <= 0.0 else gap / w0
    free = (-w0 + math.sqrt(w0 * w0 + 2.0 * accel * gap)) / accel  # full thrust all the way
    if math.isinf(high):
        return free
    high = max(high, w0)  # already faster than the bound: it may keep that speed, not gain more
    t_cap = (high - w0) / accel  # until the speed bound
    gap_cap = w0 * t_cap + 0.5 * accel * t_cap ** 2
    if gap <= gap_cap:
        return free
    return math.inf if high <= 0.0 else t_cap + (gap - gap_cap) / high


def least_time_1d_s(distance: float, w0: float, w1: float, accel: float, low: float = -math.inf,
                    high: float = math.inf) -> float:
    """The least time (s) in which a one-dimensional double integrator with ``|a| <= accel`` (m/s^2) and its
    velocity in ``[low, high]`` (m/s) moves ``distance`` (m) from velocity ``w0`` to ``w1``; inf if it cannot
    (an end velocity outside the range, or no acceleration).

    For a duration T >= |w1 - w0| / accel the reachable displacements form the interval [D_lo(T), D_hi(T)]:
    D_hi accelerates to a peak (capped at ``high``) and brakes to w1, D_lo the mirror. D_hi is convex in T
    (its slope is the peak velocity) and D_lo concave, so the least T is the shortest duration or a root of
    D_hi(T) = distance or D_lo(T) = distance: each a quadratic or linear piece, solved in closed form."""
    tol = 1e-12
    if not (low - tol <= w0 <= high + tol and low - tol <= w1 <= high + tol):
        return math.inf
    if accel <= _EPS:
        return 0.0 if abs(distance) < tol and abs(w1 - w0) < tol else (
            distance / w0 if abs(w1 - w0) < tol and w0 != 0 and distance / w0 > 0 else math.inf)
    t0 = abs(w1 - w0) / accel
    candidates = [t0] + _roots(distance, w0, w1, accel, high) + _roots(-distance, -w0, -w1, accel, -low)
    for t in sorted(c for c in candidates if c >= t0 - 1e-12):
        t = max(t, t0)
        lo = -_d_hi(t, -w0, -w1, accel, -low)
        hi = _d_hi(t, w0, w1, accel, high)
        scale = 1e-9 * max(1.0, abs(distance))
        if lo - scale <= distance <= hi + scale:
            return t
    return math.inf


def _d_hi(t: float, w0: float, w1: float, accel: float, high: float) -> float:
    """The largest displacement in time t (>= |w1 - w0| / accel) from w0 to w1, velocity at most ``high``."""
    peak = 0.5 * (accel * t + w0 + w1)
    if peak <= high:
        return (2.0 * peak * peak - w0 * w0 - w1 * w1) / (2.0 * accel)
    t_up, t_down = (high - w0) / accel, (high - w1) / accel
    return (2.0 * high * high - w0 * w0 - w1 * w1) / (2.0 * accel) + high * (t - t_up - t_down)


def _roots(distance: float, w0: float, w1: float, accel: float, high: float) -> list[float]:
    """The durations t at which D_hi(t) = distance: on the uncapped piece a quadratic in the peak velocity
    (peak = (accel t + w0 + w1) / 2, peak^2 = accel distance + (w0^2 + w1^2) / 2), on the capped piece linear."""
    out = []
    square = accel * distance + 0.5 * (w0 * w0 + w1 * w1)
    if square >= 0.0:
        for peak in (math.sqrt(square), -math.sqrt(square)):
            if peak <= high:
                out.append((2.0 * peak - w0 - w1) / accel)
    if math.isfinite(high) and high > _EPS:
        t_up, t_down = (high - w0) / accel, (high - w1) / accel
        base = (2.0 * high * high - w0 * w0 - w1 * w1) / (2.0 * accel)
        out.append(t_up + t_down + (distance - base) / high)
    return [t for t in out if math.isfinite(t) and t >= 0.0]
