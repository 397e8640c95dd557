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
from planners.plan import Plan


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
    out, last = [], {}
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


def unflyable_side_switches(plan: Plan, scenario: Scenario, after_s: float = -math.inf) -> list[SideSwitch]:
    """The side switches (second impact after ``after_s``) for which the robot has less time between
    ``max(t1, after_s)`` and t2 than :meth:`SideSwitch.time_to_get_round_s` says it needs. The planner's
    point robot flies through the object; the disc robot, held off it by its keep-off, does not get round
    an object that moves away from it unless it has that time (measured on ``two_objects``)."""
    return [sw for sw in side_switches(plan, after_s)
            if sw.time_to_get_round_s(scenario.body(sw.robot), scenario.body(sw.object))
            > sw.t2_s - max(sw.t1_s, after_s)]


__all__ = ["SideSwitch", "side_switches", "unflyable_side_switches"]
