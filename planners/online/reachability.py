"""Can a robot still make the contact of its next planned impact? (the mission monitor's reachability check)

The mission monitor (:mod:`planners.online.mission`) predicts each object's flight assuming that its next
planned impact delivers what the local layer asks for (the replanner re-aims it, Eq. 29). That holds only
while the robot can get to the contact in time. This module decides, from the observed states, when it
provably cannot.

**The contact** is the one the local layer would ask for (:class:`planners.online.reference.PlanContact`): the
object's state at the impact time by free flight from its observed state, the velocity it must leave with
(:func:`planners.online.reference.desired_object_velocity`) and the circular impact model's closed-form
inverse (:func:`planners.online.impact_model.required_contact`, Eq. 6-7) with the expert's current model of
the pair (the identified restitution and masses when identification is on). It gives the robot's centre at
contact and its velocity just before.

**The test.** The robot must fly from its observed state (position, velocity) at ``t`` to that contact state
at the impact time ``t_i``. The replanner's segment class (a degree-``DEGREE`` Bezier curve with fixed end
states) cannot do it within the robot's thrust exactly when the closed form
:func:`planners.online.segment_feasibility.bounds_feasible` says so. Three choices keep a False verdict on
the side of "really unreachable" (a wrongly pessimistic prediction triggers re-plans that lose margin):

- the acceleration bound is the robot's FULL thrust over its mass, not the replanner's ``thrust_fraction``
  share of it (the MPC's input bounds allow all of it), per world axis at the robot's observed heading
  (``(Fx |cos theta| + Fy |sin theta|) / m`` along x, likewise along y: the box of body-frame thrusts, rotated;
  at heading 0 the replanner's per-axis bound). A segment the replanner reaches only by raising its
  acceleration bound up to the robot's thrust is not flagged;
- no velocity bound: when the contact needs the robot faster than ``velocity_bound_mps`` (or the robot is
  faster now), the replanner gives the bound up (:func:`planners.online.replanner.replan_segment` falls
  back to its unbounded closed form) and the MPC, which has no velocity constraint, flies it. The speed the
  contact needs is still compared with the bound and reported (``contact_speed_above_bound``), but a contact
  that is only too fast for the bound is flown, so it is not called unreachable;
- the acceleration bound is loosened by the replanner's own tolerance (``FEASIBILITY_TOL``, the default of
  ``bounds_feasible``), so a segment the replanner would accept is never ruled out.

What a False verdict proves, and what it does not: no segment of the replanner's class joins the two states
within the robot's thrust, so the local layer has to ask for more than the robot has, the MPC saturates, and
the contact comes late, slow or not at all (measured on ``relay`` at e = 0.15: late by 0.4-0.8 s or missed).
A robot that is not restricted to Bezier curves could do a little better (from rest to rest the degree-10
class reaches 8/9 of the bang-bang displacement, 2 A T^2 / 9 against A T^2 / 4), a robot that turns could
get up to sqrt(2) more thrust along a diagonal (the MPC holds the heading), and an unplanned contact could
change its velocity on the way: the verdict is about the local layer's segments, not a bound on every
trajectory.

Only an impact that is the robot's next one is tested: if the robot has an earlier pending impact (still
being approached, within ``late_grace_s`` of its time) its velocity changes there and its current state
says nothing about the later contact.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from impact_env.scenario import Body
from planners.errors import ReplanInputError
from planners.online.impact_model import ContactPlan, required_contact
from planners.online.reference import desired_object_velocity
from planners.online.segment_feasibility import FEASIBILITY_TOL, bounds_feasible
from planners.online.segment_qp import DEGREE
from planners.plan import Plan, PlannedImpact


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
    fx, fy = (float(f) for f in robot.thrust_limit_N)
    c, s = abs(math.cos(heading_rad)), abs(math.sin(heading_rad))
    return (fx * c + fy * s) / robot.mass_kg, (fx * s + fy * c) / robot.mass_kg


def contact_reachable(t: float, impact: PlannedImpact, plan: Plan, robot: Body, robot_state, obj: Body,
                      object_state, restitution: float, masses: tuple[float, float],
                      aim_final_position: bool = False, tol: float = FEASIBILITY_TOL) -> Reachability:
    """Whether ``robot`` can still make the contact of ``impact`` on ``obj`` (see the module docstring).

    ``robot_state`` / ``object_state``: observed at time ``t`` (s), ``[x, y, theta, vx, vy, omega]`` (m, rad,
    m/s, rad/s), the object flying freely until the impact; ``restitution`` and ``masses`` (robot, object;
    kg): the pair's model (identified or the scenario file's); ``aim_final_position``: as the contact strategy
    (:class:`planners.online.reference.PlanContact`)."""
    if robot.thrust_limit_N is None:
        raise ReplanInputError(f"body {robot.name!r} has no thrust limits: it is not a robot")
    duration = impact.time_s - t
    if duration <= 0.0:
        return Reachability(t, impact, True)
    robot_state, object_state = np.asarray(robot_state, float), np.asarray(object_state, float)
    v_o = object_state[3:5]
    x_o = object_state[:2] + v_o * duration
    v_des = desired_object_velocity(plan, impact, x_o, aim_final_position)
    m_r, m_o = masses
    contact = required_contact(x_o, v_o, v_des, m_r, robot.radius_m, m_o, obj.radius_m, restitution)
    if contact is None:
        return Reachability(t, impact, True)
    v1 = contact.robot_velocity_before
    too_fast = robot.velocity_bound_mps is not None and bool(
        np.any(np.abs(v1) > np.asarray(robot.velocity_bound_mps, float) + tol))
    reachable = bounds_feasible(robot_state[:2], robot_state[3:5], contact.robot_position, v1, duration, DEGREE,
                                None, robot_acceleration_bound(robot, float(robot_state[2])), tol)
    return Reachability(t, impact, reachable, contact, too_fast)


__all__ = ["Reachability", "contact_reachable", "robot_acceleration_bound"]
