"""Can a robot still make the contact of its next planned impact? (the mission monitor's reachability check)

The mission monitor (:mod:`planners.online.mission`) predicts each object's flight assuming that its next
planned impact delivers what the local layer asks for (the replanner re-aims it, Eq. 29). That holds only
while the robot can get to the contact in time; this module decides, from the observed states, when it
provably cannot. The contact is the one the local layer would ask for (the reference's
:class:`~planners.online.reference.PlanContact` and the disc law's inverse, with the expert's current model
of the pair). The test is the closed form of :mod:`planners.online.segment_feasibility` at the robot's full
thrust, for a contact box (``position_tolerance_m``, ``velocity_tolerance_mps`` per axis) rather than the
exact contact state (:func:`box_reachable`).

A False verdict is a proof about the local layer's segments, so a wrong verdict never triggers a re-plan;
it is not a bound on every trajectory. Only an impact that is the robot's next one is tested. Why each
choice, the box test's proof and the measurements behind it: ``docs/expert_design.md#reachability``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from impact_env.config_checks import check_value
from impact_env.geometry import ConvexPolygon
from impact_env.transport.scenario import Body
from planners.errors import ReplanInputError
from planners.online.impact_model import ContactPlan
from planners.online.reference import ContactQuery, PlanContact
from planners.online.segment_feasibility import FEASIBILITY_TOL, velocity_sum_range
from planners.online.segment_qp import DEGREE
from planners.plan import Plan, PlannedImpact

POSITION_TOLERANCE_M = 0.05  # default contact box: an eighth of the contact distance of two 0.2 m discs
LATE_SAMPLES = 6  # delays tested from 0 to late_s (0.1 s apart at the expert's 0.5 s of grace)
VELOCITY_TOLERANCE_MPS = 0.1  # default contact box: the object's outcome within (1 + e) m_R / (m_R + m_O) of it
# (measured: 0.05 m/s called ping_pong_stop's return unreachable when the model's e was 0.2 below the
# simulator's, and the contact came 0.07 s late and delivered; 0.1 and 0.2 both keep relay at e = 0.15 found)


@dataclass(frozen=True)
class Reachability:
    """The verdict on one pending impact at time ``t_s``.

    ``reachable``: False only when proven unreachable (see the module docstring); ``contact``: the contact
    the local layer would ask for (None if the object needs no velocity change there, or the impact is
    due now); ``contact_speed_above_bound``: that contact needs the robot faster than its velocity bound on
    some axis (reported, not part of the verdict: the local layer then flies it without the bound).
    """

    t_s: float
    impact: PlannedImpact
    reachable: bool
    contact: ContactPlan | None = None
    contact_speed_above_bound: bool = False

    def describe(self) -> str:
        """``"R3-O1 at 25.00 s"`` (with ``", contact above the speed bound"`` when it is)."""
        imp = self.impact
        return (f"{imp.robot}-{imp.object} at {imp.time_s:.2f} s"
                + (", contact above the speed bound" if self.contact_speed_above_bound else ""))


def robot_acceleration_bound(robot: Body, heading_rad: float = 0.0) -> tuple[float, float]:
    """Per world axis, the largest acceleration (m/s^2) the robot's full thrust gives at this heading: the box
    of body-frame thrusts ``|Fx| <= thrust_limit_N[0]``, ``|Fy| <= thrust_limit_N[1]`` rotated by the heading,
    over the mass (at heading 0 the thrust limits over the mass, the replanner's per-axis bound)."""
    if robot.thrust_limit_N is None:
        raise ReplanInputError(f"body {robot.name!r} has no thrust limits: it is not a robot")
    fx, fy = (float(f) for f in robot.thrust_limit_N)
    c, s = abs(math.cos(heading_rad)), abs(math.sin(heading_rad))
    return (fx * c + fy * s) / robot.mass_kg, (fx * s + fy * c) / robot.mass_kg


def box_reachable(p0, v0, p1, v1, duration_s: float, degree: int, acceleration_bound,
                  position_tolerance_m: float = 0.0, velocity_tolerance_mps: float = 0.0,
                  tol: float = FEASIBILITY_TOL, velocity_bound=None) -> bool:
    """True if a degree-``degree`` Bezier curve of ``duration_s`` s from (p0, v0) with its acceleration control
    points within ``acceleration_bound`` (m/s^2 per axis, loosened by ``tol``) and, if given, its velocity
    control points within ``velocity_bound`` (m/s per axis, loosened by ``tol``; False when |v0| exceeds it)
    ends within ``position_tolerance_m`` of p1 and ``velocity_tolerance_mps`` of v1 on each axis; exact
    (module docstring). With zero tolerances: ``bounds_feasible(p0, v0, p1, v1, duration_s, degree,
    velocity_bound, acceleration_bound, tol)``."""
    if not duration_s > 0:
        raise ReplanInputError(f"duration_s must be > 0, got {duration_s}")
    if not degree >= 3:
        raise ReplanInputError(f"degree must be >= 3 (two fixed control points at each end), got {degree}")
    for name, value in (("position_tolerance_m", position_tolerance_m),
                        ("velocity_tolerance_mps", velocity_tolerance_mps)):
        check_value(name, value, ReplanInputError, low=0)
    acc = np.asarray(acceleration_bound, float) + tol
    if not (acc.shape == (2,) and (acc >= 0).all()):
        raise ReplanInputError(f"acceleration_bound must be >= 0 per axis, got {acceleration_bound}")
    p0, v0, p1, v1 = (np.asarray(x, float) for x in (p0, v0, p1, v1))
    speed = None if velocity_bound is None else np.asarray(velocity_bound, float) + tol
    v_lo = np.maximum(v1 - velocity_tolerance_mps, v0 - acc * duration_s)  # condition (b)
    v_hi = np.minimum(v1 + velocity_tolerance_mps, v0 + acc * duration_s)
    if speed is not None:  # condition (a): both end velocities within the bound
        if (np.abs(v0) > speed).any():
            return False
        v_lo, v_hi = np.maximum(v_lo, -speed), np.minimum(v_hi, speed)
    if (v_lo > v_hi).any():
        return False
    slack = tol * degree  # as in bounds_feasible: tol on each of the d velocity control points
    s_low = degree * (p1 - position_tolerance_m - p0) / duration_s
    s_high = degree * (p1 + position_tolerance_m - p0) / duration_s
    least, _ = velocity_sum_range(v0, v_lo, duration_s, degree, speed, acc)
    _, largest = velocity_sum_range(v0, v_hi, duration_s, degree, speed, acc)
    return bool((largest + slack >= s_low).all() and (least - slack <= s_high).all())


def contact_reachable(t: float, impact: PlannedImpact, plan: Plan, robot: Body, robot_state, obj: Body,
                      object_state, restitution: float, masses: tuple[float, float],
                      aim_final_position: bool = False, position_tolerance_m: float = POSITION_TOLERANCE_M,
                      velocity_tolerance_mps: float = VELOCITY_TOLERANCE_MPS, late_s: float = 0.0,
                      thrust_scale: float = 1.0, speed_limited: bool = False,
                      held: dict[str, ConvexPolygon] | None = None) -> Reachability:
    """Whether ``robot`` can still make the contact of ``impact`` on ``obj`` (see the module docstring).

    ``robot_state`` / ``object_state``: observed at time ``t`` (s), ``[x, y, theta, vx, vy, omega]`` (m, rad,
    m/s, rad/s), the object flying freely until the impact; ``restitution`` and ``masses`` (robot, object;
    kg): the pair's model (identified or the scenario file's); ``aim_final_position``: as the contact strategy
    (:class:`planners.online.reference.PlanContact`); the tolerances: the contact box (m, m/s per axis);
    ``late_s``: the contact also counts when it is made up to this long after the impact time (tested at
    ``LATE_SAMPLES`` delays from 0 to ``late_s``; the object is then where its free flight has taken it): the
    expert keeps approaching a planned impact that long (``ExpertConfig.late_grace_s``), and a contact that
    comes that late still delivers most of what was asked. Measured on ``relay`` in the combined condition
    (e = 0.95): R3's contact at 25 s, after getting round O1, was out of reach at the planned time from 21 s
    on, came 0.51 s late with the object 0.029 m/s off, and the mission delivered +0.43 m; predicted lost,
    it was re-planned away and the episode ended with +0.27 m (4 of 50 episodes).

    ``thrust_scale`` (> 0) scales the robot's full thrust: below 1 with ``speed_limited``, the stricter test of
    a plan about to be flown (the mission layer's acceptance of a re-plan, :func:`next_contacts`): only that
    share of the thrust, and the robot's velocity bound kept on the way (raised, per axis, to its observed
    speed or the contact's where either is faster: a contact that is only too fast for the bound is flown,
    ``docs/background.md#online``); above 1, whether a contact is out of reach by more than a margin (the
    mission layer's decisive drop). ``held``: as the contact strategy's (the final aim in a held goal's region).
    """
    if impact.time_s - t <= 0.0:
        return Reachability(t, impact, True)
    check_value("late_s", late_s, ReplanInputError, low=0)
    check_value("thrust_scale", thrust_scale, ReplanInputError, low=0, low_open=True)
    robot_state, object_state = np.asarray(robot_state, float), np.asarray(object_state, float)
    v_o = object_state[3:5]
    strategy = PlanContact(aim_final_position, held)
    acceleration = thrust_scale * np.asarray(robot_acceleration_bound(robot, float(robot_state[2])))
    speed = None
    if speed_limited and robot.velocity_bound_mps is not None:
        speed = np.maximum(np.asarray(robot.velocity_bound_mps, float), np.abs(robot_state[3:5]))
    delays = [0.0] if late_s == 0.0 else np.linspace(0.0, late_s, LATE_SAMPLES)
    first = None
    for delay in delays:  # the first delay at which the contact is within reach decides
        duration = impact.time_s + float(delay) - t
        x_o = object_state[:2] + v_o * duration
        contact = strategy.contact(ContactQuery(t, robot, obj, impact, plan, x_o, v_o, restitution, masses))
        if contact is None:
            return Reachability(t, impact, True)
        v1 = contact.robot_velocity_before
        too_fast = robot.velocity_bound_mps is not None and bool(
            np.any(np.abs(v1) > np.asarray(robot.velocity_bound_mps, float) + FEASIBILITY_TOL))
        reachable = box_reachable(robot_state[:2], robot_state[3:5], contact.robot_position, v1, duration, DEGREE,
                                  acceleration, position_tolerance_m, velocity_tolerance_mps,
                                  velocity_bound=None if speed is None else np.maximum(speed, np.abs(v1)))
        verdict = Reachability(t, impact, reachable, contact, too_fast)
        if verdict.reachable:
            return verdict
        first = first or verdict
    if first is None:  # (there is always a first delay, 0)
        raise ReplanInputError("internal: no delay of the contact was tried")
    return first


def next_contacts(t: float, plan: Plan, robots, bodies, states: dict[str, np.ndarray], model,
                  aim_final_position: bool, thrust_fraction: float, position_tolerance_m: float,
                  velocity_tolerance_mps: float, held: dict[str, ConvexPolygon] | None = None) -> list[Reachability]:
    """The stricter verdict (``thrust_fraction``, speed-limited) on each robot's first impact after ``t`` in
    ``plan``: can every robot fly its next segment of a plan about to be flown? The object's state at the
    impact is its free flight from its observed state, or the plan's when another impact on it comes first.

    ``robots``: the robots' :class:`Body` s; ``bodies(name)``: any body's; ``states``: name -> observed
    ``[x, y, theta, vx, vy, omega]`` at ``t``; ``model(robot, object)``: (restitution, (m_robot, m_object))."""
    out = []
    for robot in robots:
        mine = [i for i in plan.impacts if i.robot == robot.name and i.time_s > t + 1e-9]
        if not mine:
            continue
        first = min(mine, key=lambda i: i.time_s)
        object_state = np.asarray(states[first.object], float)
        if any(i.object == first.object and t + 1e-9 < i.time_s < first.time_s - 1e-9 for i in plan.impacts):
            p, v = plan.position(first.object, first.time_s), plan.velocity(first.object, first.time_s - 1e-6)
            object_state = np.array([*(p - v * (first.time_s - t)), 0.0, *v, 0.0])  # flies into the plan's state
        restitution, masses = model(robot.name, first.object)
        out.append(contact_reachable(t, first, plan, robot, states[robot.name], bodies(first.object), object_state,
                                     restitution, masses, aim_final_position, position_tolerance_m,
                                     velocity_tolerance_mps, 0.0, thrust_fraction, speed_limited=True, held=held))
    return out


__all__ = ["LATE_SAMPLES", "POSITION_TOLERANCE_M", "VELOCITY_TOLERANCE_MPS", "Reachability", "box_reachable",
           "contact_reachable", "next_contacts", "robot_acceleration_bound"]
