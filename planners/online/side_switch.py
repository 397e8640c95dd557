"""Side switches: one robot hitting one object twice in a row from opposite sides (the mission re-plan's check).

The offline planner's bodies are points, so a plan can have one robot push an object from behind and then
stop it from the front: the point robot simply flies through the object in between. A disc robot has to get
round an object that moves away from it. Measured on ``two_objects``: with less time than getting round
takes, the robot either does not get past in time or meets the object from the wrong side (the stop becomes
a push out of the goal). :class:`planners.online.mission.MissionPlanner` refuses a re-plan with a side switch
the robot has no time for (:func:`unflyable_side_switches`, unless ``MissionConfig.allow_side_switches``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from impact_env.transport.scenario import Body, Scenario
from planners.online.impact_model import required_contact
from planners.online.reachability import box_reachable, robot_acceleration_bound
from planners.online.segment_qp import DEGREE
from planners.plan import Plan, PlannedImpact


@dataclass
class SideSwitch:
    """Two consecutive impacts on one object by one robot whose velocity changes are more than 90 degrees
    apart: the robot touches the object on the side opposite to the change (the contact normal is the
    change's direction, Eq. 6-7), so between the two it must get round to the object's other side.

    ``angle_rad``: between the two changes; ``away_mps``: the object's planned speed away from the robot
    after the first impact (along the first change; < 0: it comes toward the robot)."""

    robot: str
    object: str
    t1_s: float
    t2_s: float
    angle_rad: float
    away_mps: float

    def time_to_get_round_s(self, robot: Body, obj: Body) -> float:
        """A lower bound of the time the robot needs: the arc of ``angle_rad`` at the contact distance
        r_R + r_O, flown at the robot's smaller axis speed bound less the object's speed away from it (inf if
        the object is as fast as the robot; 0 if the robot has no speed bound). Only a bound: the online
        layer plans no way round (the reference goes through the object, the keep-off holds the robot
        behind it), so a robot with this time can still fail to get round."""
        if robot.velocity_bound_mps is None:
            return 0.0
        relative = min(robot.velocity_bound_mps) - max(self.away_mps, 0.0)
        if relative <= 0.0:
            return math.inf
        return self.angle_rad * (robot.radius_m + obj.radius_m) / relative


def side_switches(plan: Plan, after_s: float = -math.inf) -> list[SideSwitch]:
    """The plan's :class:`SideSwitch` es whose second impact is later than ``after_s`` (the first may be
    earlier)."""
    out: list[SideSwitch] = []
    last: dict[str, PlannedImpact] = {}
    for imp in sorted(plan.impacts, key=lambda i: i.time_s):
        change = np.subtract(imp.object_velocity_after, imp.object_velocity_before)
        prev = last.get(imp.object)
        last[imp.object] = imp
        if prev is None or prev.robot != imp.robot or imp.time_s <= after_s:
            continue
        first = np.subtract(prev.object_velocity_after, prev.object_velocity_before)
        sizes = float(np.linalg.norm(first)), float(np.linalg.norm(change))
        if min(sizes) <= 1e-6 or float(first @ change) >= 0.0:
            continue
        angle = math.acos(float(np.clip(first @ change / (sizes[0] * sizes[1]), -1.0, 1.0)))
        away = float(np.dot(prev.object_velocity_after, first / sizes[0]))
        out.append(SideSwitch(imp.robot, imp.object, prev.time_s, imp.time_s, angle, away))
    return out


def unflyable_side_switches(plan: Plan, scenario: Scenario, after_s: float = -math.inf, margin: float = 1.0,
                            robot_states: dict[str, np.ndarray] | None = None, model=None,
                            tolerances: tuple[float, float] = (0.0, 0.0)) -> list[SideSwitch]:
    """The side switches (second impact after ``after_s``) the robot cannot fly, with ``margin`` (in (0, 1]):
    it has less than ``time_to_get_round_s / margin`` between ``max(t1, after_s)`` and t2. The planner's
    point robot flies through the object; the disc robot, held off it by its keep-off, does not get round
    an object that moves away from it unless it has that time (measured on ``two_objects``).

    With ``robot_states`` (name -> observed ``[x, y, theta, vx, vy, omega]`` at ``after_s``) and ``model``
    (``model(robot, object)`` -> (restitution, (m_robot, m_object))), also those whose way from the first
    contact to the second has no segment within ``margin`` of the robot's thrust and within its speed bound
    (:func:`switch_segment_feasible`, the closed form of :mod:`planners.online.segment_feasibility`), when the
    first contact is still ahead (once it is past, the second is the robot's next contact, which the mission
    layer tests from the observed state, :func:`planners.online.reachability.next_contacts`)."""
    out = []
    for sw in side_switches(plan, after_s):
        robot, obj = scenario.body(sw.robot), scenario.body(sw.object)
        if sw.time_to_get_round_s(robot, obj) > margin * (sw.t2_s - max(sw.t1_s, after_s)):
            out.append(sw)
        elif robot_states is not None and sw.t1_s > after_s and not switch_segment_feasible(
                sw, plan, robot, obj, after_s, robot_states[sw.robot], model, margin, tolerances):
            out.append(sw)
    return out


def switch_segment_feasible(sw: SideSwitch, plan: Plan, robot: Body, obj: Body, t: float, robot_state, model,
                            thrust_fraction: float, tolerances: tuple[float, float] = (0.0, 0.0)) -> bool:
    """Is there a replanner segment (degree ``DEGREE``) from the robot's state after the switch's first contact
    (its observed ``robot_state`` at ``t`` if that contact is past) to its state at the second, within
    ``thrust_fraction`` of its full thrust and within its speed bound (raised to its speed at either end where
    that is faster), ending within ``tolerances`` (m, m/s per axis) of the second contact? The contacts are the
    disc law's inverse (Eq. 6-7) of the planned object velocities, with ``model``'s restitution and masses.
    A necessary condition only: the segment may pass through the object; the time to get round it is
    :meth:`SideSwitch.time_to_get_round_s`."""
    def impact_at(time_s: float):
        return next(i for i in plan.impacts if i.robot == sw.robot and i.object == sw.object
                    and abs(i.time_s - time_s) < 1e-9)

    restitution, (m_r, m_o) = model(sw.robot, sw.object)

    def contact(imp):
        return required_contact(imp.position, imp.object_velocity_before, imp.object_velocity_after, m_r,
                                robot.radius_m, m_o, obj.radius_m, restitution)

    state = np.asarray(robot_state, float)
    first, second = contact(impact_at(sw.t1_s)), contact(impact_at(sw.t2_s))
    if second is None:
        return True
    if sw.t1_s > t and first is not None:
        start, p0, v0 = sw.t1_s, first.robot_position, first.robot_velocity_after
    else:
        start, p0, v0 = t, state[:2], state[3:5]
    if sw.t2_s - start <= 1e-9:
        return True
    acceleration = thrust_fraction * np.asarray(robot_acceleration_bound(robot, float(state[2])))
    speed = None
    if robot.velocity_bound_mps is not None:
        speed = np.maximum.reduce([np.asarray(robot.velocity_bound_mps, float), np.abs(v0),
                                   np.abs(second.robot_velocity_before)])
    return box_reachable(p0, v0, second.robot_position, second.robot_velocity_before, sw.t2_s - start, DEGREE,
                         acceleration, tolerances[0], tolerances[1], velocity_bound=speed)


__all__ = ["SideSwitch", "side_switches", "switch_segment_feasible", "unflyable_side_switches"]
