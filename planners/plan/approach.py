"""Approaches: a robot's way to its first impact must get round the object when the object is in the way.

The planners' bodies are points, so a plan may have a robot fly through the object to reach its side of
contact at its first impact (the corridor's IR plan: R2 starts above O1 and must push it up from below). A
disc robot has to get round it. This is the hand-over's test (:mod:`planners.plan.handover`) with the way
starting where the robot is when the object's last flight before the impact starts:

- nothing hits the object before: from the robot's start state, in the frame of the object flying from its
  start at its start velocity, for the whole time up to the impact;
- another robot hits it first (the last of those at t_a): from the robot's planned state at t_a (its curve;
  it has hit nothing yet), in the frame of the object after that impact, for the time from t_a. Before t_a the
  object is elsewhere, so nothing is known of getting round it then.

With ``later=True`` the same test covers each later impact of a robot whose previous impact was on another object
(one robot serving two objects: it pushes O2, then must reach the far side of O1): the way starts at that
previous impact, from the robot's state after it (its curve) and the object's state then (its curve: it flies
freely), or at the last impact on the object after that, as above. A robot whose previous impact was on the same
object makes a hand-over instead.

The way needs getting round when the straight segment from the robot's relative position to its contact
point ``-d n`` enters the disc of radius d = r_R + r_O (``r0 . r1 < d^2``); then its least time is
:func:`least_time_round_s` (a lower bound at the thrust limit), and the plan needs ``1 + margin`` times it,
the hand-overs' margin (:class:`planners.offline.config.HandoverConfig`). Derivation:
``docs/planner_design.md#hand-overs``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from impact_env.transport.scenario import Scenario
from planners.errors import PlanCheckError
from planners.plan.handover import least_time_round_s, needed_text, time_suffices, unit_change
from planners.plan.types import PlanLike, PlannedImpact

__all__ = ["Approach", "approaches", "unflyable_approaches", "way_blocked"]


@dataclass
class Approach:
    """A robot's way to its first impact (on ``object`` at ``t1_s``) that must get round the object, from
    ``t0_s`` (0: its start; else the impact ``by`` another robot that last sent the object off before); or to a
    later impact, from its previous impact ``after`` on another object (at ``after.time_s``; ``t0_s`` is that,
    or a later impact ``by`` another robot on the object).

    ``needed_s``: the least time getting there takes (inf if the object is faster than the robot can be);
    ``available_s``: ``t1_s - t0_s``; ``impact``: the impact it approaches."""

    robot: str
    object: str
    t0_s: float
    t1_s: float
    needed_s: float
    by: str | None = None
    impact: PlannedImpact | None = field(default=None, repr=False, compare=False)
    after: PlannedImpact | None = field(default=None, repr=False, compare=False)

    @property
    def available_s(self) -> float:
        return self.t1_s - self.t0_s

    def flyable(self, margin: float) -> bool:
        """True if the time there is is at least ``1 + margin`` times the least time (as a hand-over's)."""
        return time_suffices(self.available_s, self.needed_s, margin)

    def describe(self, margin: float | None = None) -> str:
        need = needed_text(self.needed_s, margin)
        if self.by is not None:
            start = f"{self.by}'s impact at {self.t0_s:.2f} s"
        elif self.after is not None:
            start = f"its impact on {self.after.object} at {self.t0_s:.2f} s"
        else:
            start = "its start"
        which = "first impact" if self.after is None else "impact"
        return (f"{self.robot} round {self.object} to its {which} at {self.t1_s:.2f} s from {start}: "
                f"{need}, has {self.available_s:.2f} s")

    def to_dict(self) -> dict:
        """For ``plan.stats`` (finite numbers only: an infinite least time is None)."""
        out = {"robot": self.robot, "object": self.object, "t0_s": self.t0_s, "t1_s": self.t1_s, "by": self.by,
               "needed_s": None if math.isinf(self.needed_s) else self.needed_s, "available_s": self.available_s}
        if self.after is not None:
            out["after"] = {"object": self.after.object, "time_s": self.after.time_s}
        return out


def approaches(plan: PlanLike, scenario: Scenario, later: bool = False) -> list[Approach]:
    """The plan's approaches that must get round their object (see :class:`Approach`), one per robot at
    most (with ``later``, also one per later impact after an impact on another object), in time order, with
    their least times (the robot's velocity at the contact is the plan's)."""
    ordered = sorted(plan.impacts, key=lambda i: i.time_s)
    out = []
    for name in dict.fromkeys(i.robot for i in ordered):
        first = next(i for i in ordered if i.robot == name)
        if later:
            out += _later_approaches(plan, scenario, name, ordered)
        normal = unit_change(first)
        if normal is None:
            continue
        robot, obj = scenario.body(name), scenario.body(first.object)
        before = [i for i in ordered if i.object == first.object and i.time_s < first.time_s - 1e-9]
        if before:  # the object's last flight starts at another robot's impact
            last = before[-1]
            t0, by = last.time_s, last.robot
            p_obj, v_obj = np.asarray(last.position, float), np.asarray(last.object_velocity_after, float)
            curve = plan.bodies.get(name)
            if curve is None:
                raise PlanCheckError([f"the plan has no curve of {name}: its way to its first impact starts where "
                                      f"the curve has it when {last.robot} hits {first.object} at {t0:g} s"])
            p_robot, v_robot = curve.position(t0), curve.velocity(t0)
        else:
            t0, by = 0.0, None
            p_obj, v_obj = np.asarray(obj.position_m, float), np.asarray(obj.velocity_mps, float)
            p_robot, v_robot = np.asarray(robot.position_m, float), np.asarray(robot.velocity_mps, float)
        needed = _time_round(robot, obj, first, normal, p_robot, v_robot, p_obj, v_obj)
        if needed is not None:
            out.append(Approach(name, first.object, t0, first.time_s, needed, by, impact=first))
    return sorted(out, key=lambda a: a.t1_s)


def _later_approaches(plan: PlanLike, scenario: Scenario, name: str, ordered: list[PlannedImpact]) -> list[Approach]:
    """The approaches of robot ``name`` to its impacts after one on another object (see the module docstring)."""
    mine = [i for i in ordered if i.robot == name]
    curve = plan.bodies.get(name)
    out = []
    for previous, impact in zip(mine, mine[1:]):
        if previous.object == impact.object or impact.time_s <= previous.time_s + 1e-9:
            continue  # a hand-over (handover.py), or two impacts at one knot
        normal = unit_change(impact)
        if normal is None:
            continue
        if curve is None:
            raise PlanCheckError([f"the plan has no curve of {name}: its way to its impact at {impact.time_s:g} s "
                                  f"starts where the curve has it after its impact at {previous.time_s:g} s"])
        robot, obj = scenario.body(name), scenario.body(impact.object)
        between = [i for i in ordered if i.object == impact.object and previous.time_s - 1e-9 <= i.time_s
                   < impact.time_s - 1e-9]
        if between:  # another robot sends the object off after the robot's previous impact: the way starts there
            last = between[-1]
            t0, by = last.time_s, last.robot
            p_obj, v_obj = np.asarray(last.position, float), np.asarray(last.object_velocity_after, float)
            p_robot, v_robot = curve.position(t0), curve.velocity(t0)
        else:  # from the robot's state after its previous impact, the object in free flight then
            t0, by = previous.time_s, None
            p_robot, v_robot = np.asarray(curve.position(t0), float), np.asarray(previous.robot_velocity_after, float)
            body = plan.bodies.get(impact.object)
            if body is None:
                raise PlanCheckError([f"the plan has no curve of {impact.object}: {name}'s way to it starts where "
                                      f"the curve has it at {t0:g} s"])
            p_obj = np.asarray(body.position(t0), float)
            v_obj = np.asarray(body.velocity(min(t0 + 1e-6, impact.time_s)), float)  # its flight after t0
        needed = _time_round(robot, obj, impact, normal, p_robot, v_robot, p_obj, v_obj)
        if needed is not None:
            out.append(Approach(name, impact.object, t0, impact.time_s, needed, by, impact=impact, after=previous))
    return out


def way_blocked(r0, r1, distance_m: float) -> bool:
    """True if the straight way from relative position ``r0`` to the contact point ``r1`` (``|r1| = distance_m``,
    both in the object's frame) enters the disc of radius ``distance_m``: ``r0 . r1 < d^2``."""
    return float(np.dot(r0, r1)) < distance_m * distance_m - 1e-9


def _time_round(robot, obj, impact: PlannedImpact, normal, p_robot, v_robot, p_obj, v_obj) -> float | None:
    """The least time (s) from the robot's state to its contact at ``impact`` round the object flying at
    ``v_obj`` (:func:`least_time_round_s`), or None when the straight way to the contact stays outside the disc."""
    d = robot.radius_m + obj.radius_m
    r0, u0 = p_robot - p_obj, v_robot - v_obj
    r1 = -d * normal
    if not way_blocked(r0, r1, d):
        return None
    u1 = np.subtract(impact.robot_velocity_before, impact.object_velocity_before)
    return least_time_round_s(robot, v_obj, d, r0, u0, r1, u1)


def unflyable_approaches(plan: PlanLike, scenario: Scenario, margin: float, later: bool = False) -> list[Approach]:
    """The approaches with less than ``1 + margin`` times their least time."""
    return [a for a in approaches(plan, scenario, later) if not a.flyable(margin)]
