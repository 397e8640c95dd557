"""Side switches: the mission re-plan's test of a plan's hand-overs, the offline planner's test from where the
robots are.

The offline planner's bodies are points, so a plan can have one robot push an object from behind and then
stop it from the front: the point robot simply flies through the object in between. A disc robot has to get
round an object that moves away from it. Measured on ``two_objects``: with less time than getting round
takes, the robot either does not get past in time or meets the object from the wrong side (the stop becomes
a push out of the goal). :class:`planners.online.mission.MissionPlanner` refuses a re-plan with a side switch
the robot cannot fly (:func:`unflyable_side_switches`, unless ``MissionConfig.allow_side_switches``).

A side switch is a hand-over of :mod:`planners.plan.handover`, and flyable on the same test: the time there is
is at least ``1 + margin`` times the least time getting round takes at the robot's thrust limit, with the
offline planner's ``HandoverConfig.margin``. So the mission never refuses a re-plan that the planner's
hand-over repair has passed, on the same model; what it adds is the test from the observed state once the
robot is on its way round, and the expert's model of the pair (its identified restitution). A robot that hits
another object in between makes no side switch (its velocity changes there, so the least time does not hold);
once that impact is past, its next contact may still be on the far side of the object, and
:func:`unflyable_ways_round` tests it from the observed states the same way (one robot serving two objects).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from impact_env.transport.scenario import Scenario
from planners.offline.config import HandoverConfig
from planners.plan import Plan
from planners.plan.handover import (
    Handover,
    PairModel,
    contact_relative_velocity,
    handovers,
    least_time_round_s,
)
from planners.plan.types import PlannedImpact

SideSwitch = Handover
"""The mission layer's name for a hand-over (:class:`planners.plan.handover.Handover`)."""

DEFAULT_MARGIN = HandoverConfig().margin


def side_switches(plan: Plan, scenario: Scenario, after_s: float = -math.inf,
                  model: PairModel | None = None) -> list[SideSwitch]:
    """The plan's hand-overs (:func:`planners.plan.handover.handovers`, with ``model``'s law) whose second
    impact is later than ``after_s`` (the first may be earlier)."""
    return [h for h in handovers(plan, scenario, model) if h.t2_s > after_s]


def unflyable_side_switches(plan: Plan, scenario: Scenario, after_s: float = -math.inf,
                            margin: float = DEFAULT_MARGIN, states: dict[str, np.ndarray] | None = None,
                            model: PairModel | None = None,
                            observed_margin: float | None = None) -> list[SideSwitch]:
    """The side switches (second impact after ``after_s``) the robot cannot fly with ``margin``
    (``HandoverConfig.margin``: the time there is must be ``1 + margin`` times the least time,
    :meth:`Handover.flyable`); those whose first impact is past and that are tested from the observed
    ``states`` with ``observed_margin`` instead (None: ``margin``).

    A switch whose first impact is at or after ``after_s`` is tested as the offline planner tests it (with
    ``model``'s law if given: ``model(robot, object)`` -> (restitution, (m_robot, m_object))). One whose first
    impact is past is tested from where the robot is: with ``states`` (name -> observed ``[x, y, theta, vx, vy,
    omega]`` at ``after_s``) the least time from the robot's observed state relative to the object's to the
    second contact, in the time left (``Handover.from_s`` = ``after_s``), unless the robot is already round
    (the straight way to the contact misses the object: then the second impact is a plain next contact,
    :func:`planners.online.reachability.next_contacts`); without them, conservatively, the whole way round in
    the time left."""
    out = []
    for sw in side_switches(plan, scenario, after_s, model):
        m = margin
        if sw.t1_s < after_s:
            needed = (sw.needed_s if sw.second is None or states is None or sw.robot not in states
                      or sw.object not in states else
                      needed_from_state_s(sw.robot, sw.object, sw.second, scenario, states, model))
            if needed is None:
                continue
            sw = dataclasses.replace(sw, from_s=after_s, needed_s=needed)
            if observed_margin is not None and states is not None and sw.robot in states and sw.object in states:
                m = observed_margin
        if not sw.flyable(m):
            out.append(sw)
    return out


def needed_from_state_s(robot_name: str, object_name: str, contact: PlannedImpact, scenario: Scenario,
                        states: dict[str, np.ndarray], model: PairModel | None) -> float | None:
    """The least time (s) from the observed states (name -> ``[x, y, theta, vx, vy, omega]``) to the robot's
    contact at impact ``contact`` on the object, round the object's disc (:func:`least_time_round_s`, the object
    flying freely until then); None if the robot is already round: the segment to the contact stays outside
    the disc, i.e. the robot is beyond the disc's tangent at the contact (``r . r_contact >= d^2``)."""
    robot, obj = scenario.body(robot_name), scenario.body(object_name)
    r_state, o_state = np.asarray(states[robot_name], float), np.asarray(states[object_name], float)
    v_obj = o_state[3:5]
    change = np.subtract(contact.object_velocity_after, v_obj)  # what the local layer will ask of the contact
    size = float(np.linalg.norm(change))
    if size <= 1e-6:
        return 0.0
    law = model(robot_name, object_name) if model is not None else (
        scenario.restitution, (robot.mass_kg, obj.mass_kg))
    u_end = contact_relative_velocity(v_obj, contact.object_velocity_after, *law)[0]
    d = robot.radius_m + obj.radius_m
    here, at = r_state[:2] - o_state[:2], -d * change / size
    if float(here @ at) >= d * d:
        return None
    return least_time_round_s(robot, v_obj, d, here, r_state[3:5] - v_obj, at, u_end)


def unflyable_ways_round(plan: Plan, scenario: Scenario, after_s: float, states: dict[str, np.ndarray],
                         model: PairModel | None, margin: float,
                         robots: set[str] | None = None) -> list[tuple[PlannedImpact, float]]:
    """Each robot's next contact (its first impact after ``after_s``) that it must get round the object to
    make and has less than ``1 + margin`` times the least time for, from the observed ``states``: (impact,
    least time s). A side switch whose first impact is past is the case where the robot's previous impact was
    on the same object; the same holds after an impact on another object, or none (one robot serving two
    objects: a trim from the front of an object it pushed earlier, after pushing another in between). The
    test is skipped when another impact on the object comes first (its velocity is the plan's then)."""
    out = []
    for name in sorted({i.robot for i in plan.impacts}):
        if (robots is not None and name not in robots) or name not in states:
            continue
        mine = [i for i in plan.impacts if i.robot == name and i.time_s > after_s + 1e-9]
        if not mine:
            continue
        nxt = min(mine, key=lambda i: i.time_s)
        if nxt.object not in states or any(i.object == nxt.object and after_s + 1e-9 < i.time_s < nxt.time_s - 1e-9
                                           for i in plan.impacts):
            continue
        needed = needed_from_state_s(name, nxt.object, nxt, scenario, states, model)
        if needed is not None and nxt.time_s - after_s < (1.0 + margin) * needed - 1e-9:
            out.append((nxt, needed))
    return out


__all__ = ["DEFAULT_MARGIN", "SideSwitch", "needed_from_state_s", "side_switches", "unflyable_side_switches",
           "unflyable_ways_round"]
