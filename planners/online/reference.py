"""Reference selection: what each robot's MPC tracks this control step (paper Eq. 29, Sec. VII).

For each robot, each control step: when one of its planned impacts is less than ``replan_intervals`` grid
intervals away (and its previous impact is over), the replanner (Eq. 29) recomputes its pre- and post-impact
segments from its current state toward the contact a :class:`ContactStrategy` asks for; after the impact the
post-impact segment is re-solved until the robot rejoins the plan; otherwise the reference is the plan itself.
The default strategy, :class:`PlanContact`, sends the object to where the plan needs it at its next impact
(or off at its planned velocity after its last), through the disc law's inverse with the identified
restitution. The strategy is the hook for other planners' plans
(:class:`planners.online.contingency.CopyContact` flies an impact-robust plan's copies). Segments are "safe"
when :class:`SegmentLimits` are given (world box, obstacle faces and other robots).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from impact_env.geometry import ConvexPolygon
from impact_env.transport.scenario import Body, Scenario
from planners.online.impact_model import ContactPlan, required_contact
from planners.online.mpc import ImpactSpec
from planners.online.replanner import SegmentLimits, WayRound, replan_around_impact, replan_segment
from planners.online.sampling import PlanSampler
from planners.plan import Plan, PlannedImpact, Segment


@dataclass
class ContactQuery:
    """What a :class:`ContactStrategy` knows when it is asked for a contact.

    ``object_position`` / ``object_velocity``: the object's predicted state just before the impact (m, m/s);
    ``restitution`` and ``masses`` (robot, object, kg): the identified impact model for this pair.
    """

    t_s: float
    robot: Body
    obj: Body
    impact: PlannedImpact
    plan: Plan
    object_position: np.ndarray
    object_velocity: np.ndarray
    restitution: float
    masses: tuple[float, float]


class ContactStrategy(Protocol):
    """Gives the robot's contact (position, pre- and post-impact velocity) for an observed object state.

    A strategy may also have ``observe(plan, robot, t, next_impact, object_state)`` (called every step before
    the reference is chosen), ``plan_state(plan, name, times, sampled)`` (adjusts the plan's robot states the
    reference starts from and rejoins) and ``reset()``; the selector calls them when they exist."""

    def contact(self, query: ContactQuery) -> ContactPlan | None: ...


class PlanContact:
    """The spatially robust plan's strategy: send the object to its next planned impact (see module doc).

    ``aim_final_position``: after the object's LAST planned impact, also correct its position error by the
    end of the plan (leave with the planned velocity plus the error divided by the time left), instead of
    the paper's planned velocity alone. A stop that is exact but happens where the object really is (not
    where the plan had it) would otherwise leave the object short of its planned rest point for good.
    ``held``: object -> the region of its goal held to the end (:func:`held_goal_regions`): where the plan's end
    position lies in it, the aim is the region's middle instead (:func:`final_aim`)."""

    def __init__(self, aim_final_position: bool = False, held: dict[str, ConvexPolygon] | None = None) -> None:
        self.aim_final_position = aim_final_position
        self.held = held or {}

    def contact(self, query: ContactQuery) -> ContactPlan | None:
        v_des = desired_object_velocity(query.plan, query.impact, query.object_position, self.aim_final_position,
                                        self.held)
        m_r, m_o = query.masses
        return required_contact(query.object_position, query.object_velocity, v_des, m_r, query.robot.radius_m,
                                m_o, query.obj.radius_m, query.restitution)


def held_goal_regions(scenario: Scenario) -> dict[str, ConvexPolygon]:
    """Object -> the region of its one held goal that lasts to the end of the task (``G[a, b] in(O, R)`` with
    ``b`` the task's horizon); objects with none, or with two such regions, are left out."""
    from planners.online.station_keeping import held_goals  # station keeping's reading of the task

    horizon = scenario.formula.horizon_s
    regions = scenario.region_map()
    found: dict[str, set[str]] = {}
    for goal in held_goals(scenario.formula, {o.name for o in scenario.objects}):
        if goal.b_s >= horizon - 1e-9:
            found.setdefault(goal.body, set()).add(goal.region)
    return {body: regions[next(iter(names))] for body, names in found.items() if len(names) == 1}


REST_MPS = 1e-3
"""An object whose planned speed at the end is below this (m/s) is planned to end at rest."""


def final_aim(plan: Plan, obj: str, held: dict[str, ConvexPolygon] | None = None) -> np.ndarray:
    """Where an object is aimed at the end of the plan after its last impact: its planned end position, or,
    when the plan leaves it at rest there (slower than :data:`REST_MPS`) in the region of its goal held to the
    end (``held``), the region's middle (the mean of its vertices; a box's centre). The planner's rest point
    satisfies the goal by the plan's robustness, which another conjunct may set (the narrow gap's 0.15 m):
    under post-impact noise the drift the stop leaves has the whole region's half-width to use instead
    (timed_visits, narrow_gap at 0.02 m/s: stops 0.16 and 0.15 m from the goal's edge, drifting out). An
    object sent through its goal keeps the planned end: its timing over the window is the plan's (aimed at the
    middle, one_robot_two_objects' pushes lost 13 of 50 episodes at 0.02 m/s and gained 5)."""
    end = plan.bodies[obj].position(plan.tf_s)
    region = (held or {}).get(obj)
    if (region is not None and float(np.hypot(*plan.bodies[obj].velocity(plan.tf_s))) < REST_MPS
            and bool(region.contains(np.asarray(end, float)[None])[0])):
        return np.asarray(region.vertices, float).mean(axis=0)
    return end


def desired_object_velocity(plan: Plan, impact: PlannedImpact, position_at_impact: np.ndarray,
                            aim_final_position: bool = False,
                            held: dict[str, ConvexPolygon] | None = None) -> np.ndarray:
    """Leave the impact so as to be where the plan needs the object at its next impact (after the last one:
    the planned velocity, corrected toward :func:`final_aim` if ``aim_final_position``)."""
    later = [i for i in plan.impacts_of(impact.object) if i.time_s > impact.time_s + 1e-9]
    if not later:
        v = np.asarray(impact.object_velocity_after, float)
        left = plan.tf_s - impact.time_s
        if aim_final_position and left > 1e-6:
            end = final_aim(plan, impact.object, held)
            v = v + (end - (np.asarray(position_at_impact, float) + v * left)) / left
        return v
    nxt = min(later, key=lambda i: i.time_s)
    return (np.asarray(nxt.position) - position_at_impact) / (nxt.time_s - impact.time_s)


@dataclass
class Replanned:
    """A robot's replanned segments around one impact."""

    impact: PlannedImpact
    pre: Segment
    post: Segment


@dataclass
class RobotReference:
    """One step's output for one robot: the MPC's reference (N+1, 4), its impact node, and whether the robot is
    approaching ``impact`` (then the keep-off on that object is lifted shortly before it)."""

    reference: np.ndarray
    impact_spec: ImpactSpec | None
    approaching: PlannedImpact | None


class ReferenceSelector:
    """Chooses every robot's reference each step; holds the replanned segments between steps.

    Args:
        plan: the plan flown (swap with :meth:`set_plan` after a mission replan).
        grid_dt: the plan's grid interval (s); dt: the control period (s).
        strategy: the :class:`ContactStrategy` (default :class:`PlanContact` without final aiming).
        replan_intervals: replanning starts this many grid intervals before an impact.
        thrust_fraction: share of the thrust limit a replanned segment may use (see acceleration_bound).
        disc_offset: before the approach window, fly the plan shifted to where a disc meets the object
        (:meth:`_offset_toward`); box: robot -> the box its centre must stay in (for that shift).
        way_round: a pre-impact segment whose straight way to the contact crosses the object's disc gets round it
        (:class:`~planners.online.segment_qp.WayRound`, the object's free flight until the impact).
    """

    def __init__(self, plan: Plan, grid_dt: float, dt: float, strategy: ContactStrategy | None = None,
                 replan_intervals: int = 2, thrust_fraction: float = 0.8, disc_offset: bool = False,
                 box: Callable[[Body], tuple[float, float, float, float]] | None = None,
                 way_round: bool = False) -> None:
        self.grid_dt, self.dt = grid_dt, dt
        self.disc_offset, self.box = disc_offset, box
        self.way_round = way_round
        self.thrust_fraction = thrust_fraction
        self.strategy = strategy or PlanContact()
        self.replan_intervals = replan_intervals
        self.replanned: dict[str, Replanned] = {}
        self.replans = 0
        self.set_plan(plan)

    def acceleration_bound(self, robot: Body) -> tuple[float, float]:
        """Per-axis acceleration a replanned segment may ask for: ``thrust_fraction`` of the thrust limit
        (heading held, so body axes are world axes), the rest is the MPC's margin for disturbances."""
        fx, fy, _ = robot.wrench_limits
        return self.thrust_fraction * fx / robot.mass_kg, self.thrust_fraction * fy / robot.mass_kg

    def set_plan(self, plan: Plan) -> None:
        self.plan = plan
        self.sampler = PlanSampler(plan)
        self.tf = plan.tf_s
        self.replanned = {}

    def reset(self) -> None:
        self.replanned = {}
        self.replans = 0
        reset = getattr(self.strategy, "reset", None)
        if reset is not None:
            reset()

    # ------------------------------------------------------------------------------------------ step
    def robot_reference(self, robot: Body, obj_of: Callable[[str], Body], t: float, state: np.ndarray,
                        nxt: PlannedImpact | None, past_times: list[float], times: np.ndarray,
                        object_state: Callable[[str, float], tuple[np.ndarray, np.ndarray]],
                        model: Callable[[str, str], tuple[float, tuple[float, float]]],
                        limits: SegmentLimits | None) -> RobotReference:
        """The reference of ``robot`` at time ``t`` (its measured ``state`` [x, y, theta, vx, vy, omega]).

        ``nxt``: its next pending impact (or None); ``past_times``: times of its earlier impacts;
        ``object_state(name, t_target)``: an object's predicted position and velocity at ``t_target``;
        ``model(robot, object)``: the identified (restitution, (m_robot, m_object)).
        """
        name = robot.name
        observe = getattr(self.strategy, "observe", None)  # e.g. an impact-robust plan's copy blend
        if observe is not None:
            observe(self.plan, robot, t, nxt, object_state)
        window_start = 0.0
        if nxt is not None:
            window_start = max([nxt.time_s - self.replan_intervals * self.grid_dt] + [p + self.dt for p in past_times])
        current = self.replanned.get(name)
        approaching = nxt is not None and t >= window_start - 1e-9
        if approaching and nxt is not None and nxt.time_s > t + 1e-9:  # (approaching: nxt is not None)
            replanned = self._replan(robot, obj_of(nxt.object), t, state, nxt, object_state, model, limits)
            if replanned is not None:
                self.replanned[name] = current = replanned
        elif approaching:
            pass  # late: keep the last approach, continued straight at the contact velocity (see _reference)
        elif current is not None and t < current.post.t1_s:
            # after the impact: rejoin the plan from where the robot really is
            t1 = current.post.t1_s
            p1, v1 = self._plan_point(name, t1)
            current.post = replan_segment(state[:2], state[3:5], p1, v1, t, t1, robot.velocity_bound_mps, limits,
                                          self.acceleration_bound(robot))
        elif current is not None:
            del self.replanned[name]
            current = None
        approaching = approaching and current is not None and current.impact is nxt
        reference = self._reference(name, times, current, approaching)
        if self.disc_offset and nxt is not None and not approaching:
            self._offset_toward(reference, times, robot, obj_of(nxt.object), nxt, past_times, window_start)
        impact_spec = None
        if approaching and current is not None and current.pre.t1_s > t:  # (approaching: current is not None)
            k = round((current.pre.t1_s - t) / self.dt)
            if 1 <= k <= len(times) - 1:
                impact_spec = ImpactSpec(step=k, position=current.pre.control_points[-1],
                                         velocity_before=current.pre.velocity(current.pre.t1_s)[0],
                                         velocity_after=current.post.velocity(current.post.t0_s)[0])
        return RobotReference(reference, impact_spec, nxt if approaching else None)

    def _replan(self, robot: Body, obj: Body, t: float, state: np.ndarray, impact: PlannedImpact,
                object_state, model, limits: SegmentLimits | None) -> Replanned | None:
        x_o, v_o = object_state(impact.object, impact.time_s)
        restitution, masses = model(robot.name, obj.name)
        contact = self.strategy.contact(ContactQuery(t, robot, obj, impact, self.plan, x_o, v_o, restitution, masses))
        if contact is None:
            return None
        t_rejoin = min(impact.time_s + self.grid_dt, self.tf)
        if t_rejoin <= impact.time_s + 1e-9:
            t_rejoin = impact.time_s + self.grid_dt
        p1, v1 = self._plan_point(robot.name, t_rejoin)
        way_round = None
        if self.way_round:
            x_o, v_o = np.asarray(x_o, float), np.asarray(v_o, float)
            t_hit = impact.time_s

            def centre(times: np.ndarray) -> np.ndarray:  # the object's free flight to the impact
                return x_o + np.outer(np.asarray(times, float) - t_hit, v_o)

            way_round = WayRound.between(state[:2], contact.robot_position, centre, t, t_hit,
                                         robot.radius_m + obj.radius_m)
        pre, post = replan_around_impact(t, state[:2], state[3:5], impact.time_s, contact, t_rejoin, p1, v1,
                                         robot.velocity_bound_mps, limits, self.acceleration_bound(robot),
                                         way_round=way_round)
        self.replans += 1
        return Replanned(impact, pre, post)

    def _offset_toward(self, ref: np.ndarray, times: np.ndarray, robot: Body, obj: Body, impact: PlannedImpact,
                       past_times: list[float], window_start: float) -> None:
        """Shift the plan toward where a disc must be at the coming impact, in place.

        The planner's bodies are points: at a planned impact the robot's centre is at the object's. A disc
        must be ``r_R + r_O`` behind it along the contact normal, so a robot that flies the plan arrives too
        close to speed up to the contact velocity (it then backs away or arrives slow). From its last
        impact (or the start) to the approach window, the reference is the plan moved by that offset, faded
        in with a quintic smoothstep (zero velocity and acceleration at both ends); then the replanner takes
        over from a state that has the plan's velocity profile. Kept inside ``self.box`` if given."""
        dv = np.subtract(impact.object_velocity_after, impact.object_velocity_before)
        size = float(np.hypot(*dv))
        t_a = max(past_times) + self.grid_dt if past_times else 0.0
        if size < 1e-6 or window_start - t_a < self.grid_dt:
            return
        offset = -(robot.radius_m + obj.radius_m) * dv / size
        u = np.minimum(np.maximum((times - t_a) / (window_start - t_a), 0.0), 1.0)  # np.clip, less dispatch
        s = u ** 3 * (10.0 - 15.0 * u + 6.0 * u ** 2)
        ds = 30.0 * u ** 2 * (1.0 - u) ** 2 / (window_start - t_a)
        ref[:, :2] += np.outer(s, offset)
        ref[:, 2:] += np.outer(ds, offset)
        if self.box is not None:
            x0, x1, y0, y1 = self.box(robot)
            np.minimum(np.maximum(ref[:, 0], x0), x1, out=ref[:, 0])
            np.minimum(np.maximum(ref[:, 1], y0), y1, out=ref[:, 1])

    def _plan_state(self, name: str, times: np.ndarray) -> np.ndarray:
        """[x, y, vx, vy] of the plan for robot ``name`` at ``times``, as the strategy adjusts it (an
        impact-robust plan: the copy blend that matches the object's state, inside its windows)."""
        ref = self.sampler.state(name, times)
        adjust = getattr(self.strategy, "plan_state", None)
        return ref if adjust is None else adjust(self.plan, name, np.asarray(times, dtype=float), ref)

    def _plan_point(self, name: str, t: float) -> tuple[np.ndarray, np.ndarray]:
        state = self._plan_state(name, np.array([t]))[0]
        return state[:2], state[2:]

    def _reference(self, name: str, times: np.ndarray, current: Replanned | None, approaching: bool) -> np.ndarray:
        """[x, y, vx, vy] at the horizon's nodes: the replanned segments where they apply, else the plan.

        While an impact is still to come, the approach continues past the planned time straight at the
        contact velocity (a late contact is met at full speed, not braked for)."""
        if current is not None and approaching and (times <= current.pre.t1_s + 1e-9).all():
            # the whole horizon is on the approach (below, every node would be overwritten): the plan's state
            # (and the strategy's adjustment of it, which has no side effects) is not needed
            ref = np.empty((len(times), 4))
            ref[:, :2] = current.pre.position(times)
            ref[:, 2:] = current.pre.velocity(times)
            return ref
        ref = self._plan_state(name, np.minimum(times, self.tf))
        ref[times > self.tf, 2:] = 0.0
        if current is not None and approaching:
            pre = current.pre
            mask = times <= pre.t1_s + 1e-9
            ref[mask, :2] = pre.position(times[mask])
            ref[mask, 2:] = pre.velocity(times[mask])
            late = ~mask
            if np.any(late):
                p_c, v_c = pre.control_points[-1], pre.velocity(pre.t1_s)[0]
                ref[late, :2] = p_c + np.outer(times[late] - pre.t1_s, v_c)
                ref[late, 2:] = v_c
        elif current is not None:
            seg = current.post
            mask = (times >= seg.t0_s - 1e-9) & (times <= seg.t1_s + 1e-9)
            if np.any(mask):
                ref[mask, :2] = seg.position(times[mask])
                ref[mask, 2:] = seg.velocity(times[mask])
        return ref
