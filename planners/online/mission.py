"""Mission-level replanning: monitor the predicted outcome of the plan's remainder and re-plan the rest of the
mission from the current state when it leaves the plan's tolerance.

The paper's stack is open loop at the mission level: the local replanner (Eq. 29) re-aims each planned
impact, but once an impact goes wrong nothing re-decides the impacts that follow. Here, at every observed
robot-object impact and every ``check_period_s``, (1) the rest of the episode is predicted from the observed
states as the local layer will fly it, without the impacts the robot provably cannot reach
(:mod:`planners.online.reachability`); (2) when the task's predicted robustness fails the test of
:class:`MissionConfig`, (3) the offline planner re-plans the rest from the current state (a derived scenario
with the task progressed to now) and the new plan is spliced after the executed part, unless it is no better
or has a side switch the robot has no time for (:mod:`planners.online.side_switch`).

The compute budget is a node count and the solver's threads are pinned (``MissionConfig.solver_options``), so
the same observations give the same re-plan on any machine; a re-plan cut by the time limit is discarded.
The design and its measurements: ``docs/expert_design.md#mission-replanning``.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import KW_ONLY, InitVar, dataclass, field
from typing import Any

import numpy as np

from impact_env.config_checks import (
    NOT_GIVEN,
    check_flag,
    check_instance,
    check_integer,
    check_number,
    check_value,
    moved_into,
)
from impact_env.stl import progress, robustness, without_constants
from impact_env.transport.scenario import Body, Scenario
from planners import bezier
from planners.errors import PlannerError
from planners.offline.solvers.base import SolverOptions
from planners.offline.spatially_robust import PlannerConfig, plan_spatially_robust
from planners.online.reachability import POSITION_TOLERANCE_M, VELOCITY_TOLERANCE_MPS, Reachability, contact_reachable
from planners.online.sampling import PlanSampler
from planners.online.side_switch import SideSwitch, side_switches, unflyable_side_switches
from planners.plan import BodyPlan, Plan, Segment


def _replan_budget() -> SolverOptions:
    return SolverOptions(node_limit=200, time_limit_s=60.0, threads=1)


@dataclass(frozen=True)
class MissionConfig:
    """When and how the mission is re-planned (see the module docstring).

    The old keywords ``node_limit``, ``time_limit_s`` and ``threads`` are still accepted for one release, with
    a ``DeprecationWarning``, and set in :attr:`solver_options`.
    """

    check_period_s: float = 1.0
    """Prediction period between impacts (s)."""
    robustness_fraction: float = 0.5
    """Re-plan when the predicted robustness is below this share (in [0, 1]) of the flown plan's ..."""
    min_robustness_m: float = 0.0
    """... or below this (m; 0: when a failure is predicted)."""
    solver_options: SolverOptions = field(default_factory=_replan_budget)
    """A re-plan's solver budget: ``node_limit`` branch-and-bound nodes of the robustness stage (200), the
    budget; ``time_limit_s`` per planner stage (60 s), a safety net (a re-plan it cuts is discarded); ``threads``
    pinned (1: HiGHS's own choice depends on the machine's cores). The planner config's own are not used."""
    refine_nodes: int = 0
    """Branch-and-bound nodes of the planner's second stage in a re-plan (0 skips it)."""
    max_replans: int = 3
    """Re-plans per episode."""
    min_remaining_s: float = 2.0
    """No re-plan closer than this to the end (s)."""
    quiet_s: float = 1.0
    """No re-plan within this time of a pending planned impact (s): the local replanner owns it."""
    allow_side_switches: bool = False
    """Accept a re-plan with a side switch the robot has no time for (:func:`unflyable_side_switches`); False:
    keep the current plan."""
    predict_reachability: bool = True
    """The prediction drops a pending impact the robot provably cannot reach in time (step 1); False: every
    pending impact is predicted to deliver what the plan asks."""
    reach_tolerance_m: float = POSITION_TOLERANCE_M
    """How close to the contact's position (m, per axis) counts as making it (the contact box of
    :func:`planners.online.reachability.contact_reachable`; larger is more conservative)."""
    reach_tolerance_mps: float = VELOCITY_TOLERANCE_MPS
    """How close to the contact's velocity (m/s, per axis) counts as making it."""
    _: KW_ONLY
    node_limit: InitVar[Any] = NOT_GIVEN
    """Deprecated: ``solver_options.node_limit``."""
    time_limit_s: InitVar[Any] = NOT_GIVEN
    """Deprecated: ``solver_options.time_limit_s``."""
    threads: InitVar[Any] = NOT_GIVEN
    """Deprecated: ``solver_options.threads``."""

    def __post_init__(self, node_limit: Any, time_limit_s: Any, threads: Any) -> None:
        check_instance(self, "solver_options", PlannerError, SolverOptions, what="a SolverOptions")
        moved_into(self, "solver_options", {"node_limit": node_limit, "time_limit_s": time_limit_s,
                                            "threads": threads}, PlannerError)
        budget = self.solver_options
        # the same observations must give the same re-plan on every machine: a node budget, pinned threads
        check_value("MissionConfig.solver_options.node_limit", budget.node_limit, PlannerError, low=1, integer=True)
        check_value("MissionConfig.solver_options.threads", budget.threads, PlannerError, low=1, integer=True)
        check_value("MissionConfig.solver_options.time_limit_s", budget.time_limit_s, PlannerError, low=0,
                    low_open=True)
        for name in ("check_period_s", "min_remaining_s", "quiet_s"):
            check_number(self, name, PlannerError, low=0, low_open=True)
        check_number(self, "robustness_fraction", PlannerError, low=0, high=1)
        check_number(self, "min_robustness_m", PlannerError)
        for name in ("refine_nodes", "max_replans"):
            check_integer(self, name, PlannerError, low=0)
        for name in ("allow_side_switches", "predict_reachability"):
            check_flag(self, name, PlannerError)
        for name in ("reach_tolerance_m", "reach_tolerance_mps"):
            check_number(self, name, PlannerError, low=0)


@dataclass
class ReplanRecord:
    """One mission re-plan: when, why, what it gave, how long it took."""

    time_s: float
    predicted_robustness: float
    threshold_m: float
    status: str  # "accepted", "kept: <reason>"
    new_robustness: float | None = None
    solve_s: float = 0.0
    intervals: int = 0
    impacts_added: int = 0
    task: str = ""
    unreachable: list[str] = dataclasses.field(default_factory=list)  # impacts the prediction dropped


# ------------------------------------------------------------------------------------------- plans
def resample_plan(plan: Plan, t0: float, tf: float, intervals: int, degree: int) -> Plan:
    """The plan's motion on [t0, tf] expressed on a new grid of ``intervals`` equal intervals (time 0 = t0):
    robots as degree-``degree`` Bezier segments (least-squares fit of the old curve), objects as straight
    segments between their old positions at the new knots, impacts moved to the nearest new knot. A warm
    start for the planner, not a flyable plan."""
    sampler = PlanSampler(plan)
    knots = np.linspace(t0, tf, intervals + 1)
    m = 3 * (degree + 1)
    phases = np.linspace(0.0, 1.0, m)
    fit = np.linalg.pinv(bezier.bernstein(degree, phases))  # (d+1, m)
    bodies = {}
    for name, body in plan.bodies.items():
        segments = []
        for a, b in zip(knots[:-1], knots[1:]):
            if body.kind == "robot":
                pts = sampler.state(name, a + phases * (b - a))[:, :2]
                cp = fit @ pts
            else:
                cp = sampler.state(name, np.array([a, b]))[:, :2]
            segments.append(Segment(a - t0, b - t0, cp))
        bodies[name] = BodyPlan(name, body.kind, segments)
    dt = (tf - t0) / intervals
    impacts = [dataclasses.replace(i, time_s=round((i.time_s - t0) / dt) * dt) for i in plan.impacts
               if t0 < i.time_s <= tf and 1 <= round((i.time_s - t0) / dt) <= intervals]
    return Plan(plan.scenario, plan.planner, plan.robustness, bodies, impacts)


def _clip_segment(seg: Segment, t: float) -> Segment | None:
    """The part of ``seg`` before time ``t`` (None if none)."""
    if t <= seg.t0_s + 1e-12:
        return None
    if t >= seg.t1_s:
        return seg
    left, _ = bezier.split(seg.control_points, (t - seg.t0_s) / seg.duration_s)
    return Segment(seg.t0_s, t, left)


def splice(executed: Plan, remainder: Plan, t: float) -> tuple[Plan, set[int]]:
    """``executed`` on [0, t] followed by ``remainder`` (planned from time 0 = t) shifted to absolute time.

    Returns the spliced plan and the indices of its impacts that lie in the past (they count as done: the
    ones that happened were observed, the ones that did not will not be flown any more)."""
    bodies = {}
    for name, body in executed.bodies.items():
        past = [s for s in (_clip_segment(seg, t) for seg in body.segments) if s is not None]
        future = [Segment(s.t0_s + t, s.t1_s + t, np.asarray(s.control_points, float).copy())
                  for s in remainder.bodies[name].segments]
        bodies[name] = BodyPlan(name, body.kind, past + future)
    old = [i for i in executed.impacts if i.time_s <= t + 1e-9]
    new = [dataclasses.replace(i, time_s=i.time_s + t) for i in remainder.impacts]
    spliced = Plan(executed.scenario, remainder.planner, remainder.robustness, bodies, old + new,
                   remainder.solver, remainder.solve_time_s, remainder.build_time_s, remainder.mip_gap,
                   {**remainder.stats, "spliced_at_s": t})
    return spliced, set(range(len(old)))


def _initial_state(body: Body, position: np.ndarray, velocity: np.ndarray, scenario: Scenario) -> Body:
    """The body with the observed state as its initial state, nudged inside the planner's allowed box and
    with a velocity bound no smaller than its observed speed (else the derived problem starts infeasible)."""
    xmin, xmax, ymin, ymax = scenario.world_box
    x0, x1, y0, y1 = xmin + body.radius_m, xmax - body.radius_m, ymin + body.radius_m, ymax - body.radius_m
    eps = 1e-6  # the planner's box for a centre (the world shrunk by the radius), strictly inside
    p = (float(np.clip(position[0], x0 + eps, x1 - eps)), float(np.clip(position[1], y0 + eps, y1 - eps)))
    v = (float(velocity[0]), float(velocity[1]))
    bound = body.velocity_bound_mps
    if bound is not None:
        bound = (max(bound[0], abs(v[0]) * 1.01), max(bound[1], abs(v[1]) * 1.01))
    return dataclasses.replace(body, position_m=p, velocity_mps=v, velocity_bound_mps=bound)


def _without_end_states(scenario: Scenario) -> Scenario:
    """The scenario with no final position or velocity for any body (only the task is left)."""
    def free(body: Body) -> Body:
        return dataclasses.replace(body, final_position_m=None, final_velocity_mps=None)

    return dataclasses.replace(scenario, robots=tuple(free(b) for b in scenario.robots),
                               objects=tuple(free(b) for b in scenario.objects))


# ---------------------------------------------------------------------------------------- planner
class MissionPlanner:
    """Monitors the plan's predicted outcome and re-plans the rest of the mission (see the module doc).

    Args:
        scenario: the episode's scenario (the nominal model: the planner's).
        plan: the offline plan.
        config: :class:`MissionConfig`.
        planner_config: options of the offline planner that re-plans keep (thrust fraction, solver, ...).
        aim_final_position: predict, as the reference selection then flies, that after its last impact an
            object heads for its planned end position (else that it leaves with the planned velocity).
        late_grace_s: a planned impact not yet observed is still approached this long after its time (the
            expert's ``ExpertConfig.late_grace_s``): while one is, its robot and object are not tested for
            reachability.
    """

    def __init__(self, scenario: Scenario, plan: Plan, config: MissionConfig | None = None,
                 planner_config: PlannerConfig | None = None, aim_final_position: bool = False,
                 late_grace_s: float = 0.5) -> None:
        self.scenario = scenario
        self.aim_final_position = aim_final_position
        self.late_grace_s = float(late_grace_s)
        self.config = config or MissionConfig()
        self.planner_config = planner_config or PlannerConfig()
        self.dt = scenario.control_period_s
        self.formula = scenario.formula
        self.regions = scenario.region_map()
        self.names = [b.name for b in scenario.bodies]
        self.intervals = int(plan.stats.get("intervals") or len(next(iter(plan.bodies.values())).segments))
        self.degree = int(plan.stats.get("robot_degree") or
                          len(plan.bodies[scenario.robots[0].name].segments[0].control_points) - 1)
        self.grid_dt = scenario.tf_s / self.intervals
        self.reset(plan)

    def reset(self, plan: Plan) -> None:
        self.plan_robustness = plan.robustness
        self.trace: list[np.ndarray] = []
        self.records: list[ReplanRecord] = []
        self.checks = 0
        self.timeouts = 0
        self.unreachable = 0  # checks that found a pending impact unreachable
        self.verdicts: list[Reachability] = []  # the last prediction's reachability verdicts
        self._last_check = -math.inf
        self._sampler: PlanSampler | None = None
        self._sampler_plan: Plan | None = None

    # ------------------------------------------------------------------------------------ monitor
    def reachability(self, t: float, states: np.ndarray, index: dict[str, int], plan: Plan, done: set[int],
                     model) -> list[Reachability]:
        """The verdict on each object's next pending impact (time > t) that can be tested (step 1): its
        robot has no earlier impact pending and neither has a late one still approached (within
        ``late_grace_s`` of its time). ``model(robot, object)``: the pair's (restitution, (m_robot, m_object)),
        as the expert's contact inverse uses it."""
        pending = [(k, i) for k, i in enumerate(plan.impacts) if k not in done and i.time_s > t - self.late_grace_s]
        out = []
        for body in self.scenario.objects:
            mine = [i for _, i in pending if i.object == body.name]
            future = [i for i in mine if i.time_s > t]
            if not future or len(future) < len(mine):  # nothing ahead, or a late impact still approached
                continue
            first = min(future, key=lambda i: i.time_s)
            if any(i.robot == first.robot and i is not first and i.time_s <= first.time_s for _, i in pending):
                continue  # the robot has another impact first: its velocity changes there
            restitution, masses = model(first.robot, body.name)
            out.append(contact_reachable(t, first, plan, self.scenario.body(first.robot), states[index[first.robot]],
                                         body, states[index[body.name]], restitution, masses,
                                         self.aim_final_position, self.config.reach_tolerance_m,
                                         self.config.reach_tolerance_mps, self.late_grace_s))
        return out

    def predicted_trace(self, t: float, states: np.ndarray, index: dict[str, int], plan: Plan,
                        done: set[int], model=None) -> dict[str, np.ndarray]:
        """Predicted positions (samples at t, t + dt, ..., the task's horizon) of every body: see step 1.

        ``model(robot, object)`` -> (restitution, (m_robot, m_object)): the pair's model for the reachability
        test (with ``predict_reachability``; None: no test). The verdicts are kept in ``self.verdicts``."""
        self.verdicts = []
        if model is not None and self.config.predict_reachability:
            self.verdicts = self.reachability(t, states, index, plan, done, model)
        lost = {id(v.impact) for v in self.verdicts if not v.reachable}
        if self._sampler_plan is not plan:
            self._sampler, self._sampler_plan = PlanSampler(plan), plan
        sampler = self._sampler
        horizon = self.formula.horizon_s
        times = t + self.dt * np.arange(max(1, round((horizon - t) / self.dt)) + 1)
        out = {}
        for body in self.scenario.robots:
            out[body.name] = sampler.state(body.name, np.minimum(times, plan.tf_s))[:, :2]
        for body in self.scenario.objects:
            s = states[index[body.name]]
            pos = s[:2] + np.outer(times - t, s[3:5])
            pending = sorted((i for k, i in enumerate(plan.impacts)
                              if i.object == body.name and k not in done and i.time_s > t), key=lambda i: i.time_s)
            if pending and id(pending[0]) not in lost:  # a lost impact: free flight from now on
                first = pending[0]
                hit = s[:2] + s[3:5] * (first.time_s - t)
                after = times >= first.time_s
                if len(pending) > 1:
                    second = pending[1]
                    v = (np.asarray(second.position) - hit) / (second.time_s - first.time_s)
                    between = after & (times < second.time_s)
                    pos[between] = hit + np.outer(times[between] - first.time_s, v)
                    later = times >= second.time_s
                    pos[later] = sampler.state(body.name, np.minimum(times[later], plan.tf_s))[:, :2]
                else:
                    v = np.asarray(first.object_velocity_after, float)
                    left = plan.tf_s - first.time_s
                    if self.aim_final_position and left > 1e-6:  # what the local layer will ask for
                        v = v + (sampler.position(body.name, plan.tf_s) - (hit + v * left)) / left
                    pos[after] = hit + np.outer(times[after] - first.time_s, v)
            out[body.name] = pos
        return out

    def predicted_robustness(self, t: float, states: np.ndarray, index: dict[str, int], plan: Plan,
                             done: set[int], model=None) -> float:
        """The task's robustness on the executed trace followed by the prediction."""
        pred = self.predicted_trace(t, states, index, plan, done, model)
        past = np.array(self.trace)  # (k + 1, n_bodies, 2), the last sample is now
        trace = {name: np.vstack([past[:-1, i], pred[name]]) for i, name in enumerate(self.names)}
        return float(robustness(self.formula, trace, self.regions, self.dt))

    def step(self, t: float, states: np.ndarray, index: dict[str, int], plan: Plan, book, impact_observed: bool,
             model) -> tuple[Plan, set[int]] | None:
        """Record this step's observation; maybe re-plan. Returns (spliced plan, done impacts) or None."""
        self.trace.append(states[[index[n] for n in self.names], 0:2].copy())
        cfg = self.config
        if not impact_observed and t - self._last_check < cfg.check_period_s - 1e-9:
            return None
        self._last_check = t
        if len(self.records) >= cfg.max_replans or self.scenario.tf_s - t < cfg.min_remaining_s:
            return None
        pending = [i for k, i in enumerate(plan.impacts) if k not in book.done]
        if any(abs(i.time_s - t) < cfg.quiet_s for i in pending):
            return None
        self.checks += 1
        predicted = self.predicted_robustness(t, states, index, plan, book.done, model)
        if any(not v.reachable for v in self.verdicts):
            self.unreachable += 1
        threshold = max(cfg.min_robustness_m, cfg.robustness_fraction * self.plan_robustness)
        if predicted >= threshold:
            return None
        return self._replan(t, states, index, plan, predicted, threshold)

    # ------------------------------------------------------------------------------------ re-plan
    def derived_scenario(self, t: float, states: np.ndarray, index: dict[str, int]) -> tuple[Scenario, int] | None:
        """The scenario of the rest of the mission (see step 3) and its grid size; None if nothing is left
        to plan for (the past decided the task)."""
        k = len(self.trace) - 1
        trace = {name: np.array(self.trace)[:, i] for i, name in enumerate(self.names)}
        task = without_constants(progress(self.formula, trace, self.regions, self.dt, k))
        if task is None:
            return None
        sc = self.scenario
        remaining = sc.tf_s - t
        intervals = max(2, round(remaining / self.grid_dt))

        def moved(body: Body) -> Body:
            s = states[index[body.name]]
            return _initial_state(body, s[:2], s[3:5], sc)

        derived = dataclasses.replace(sc, tf_s=remaining, task=str(task), robots=tuple(moved(b) for b in sc.robots),
                                      objects=tuple(moved(b) for b in sc.objects), planner_intervals=intervals,
                                      planner_robot_degree=self.degree)
        return derived, intervals

    def _replan(self, t: float, states: np.ndarray, index: dict[str, int], plan: Plan, predicted: float,
                threshold: float) -> tuple[Plan, set[int]] | None:
        from planners.errors import InfeasiblePlanError, PlanTimeoutError

        record = ReplanRecord(t, predicted, threshold, "kept",
                              unreachable=[v.describe() for v in self.verdicts if not v.reachable])
        self.records.append(record)
        built = self.derived_scenario(t, states, index)
        if built is None:
            record.status = "kept: the past decided the task"
            return None
        derived, intervals = built
        record.intervals, record.task = intervals, derived.task
        cfg = self.config
        warm = resample_plan(plan, t, self.scenario.tf_s, intervals, self.degree)
        budget = cfg.solver_options
        # min_robustness_m=0: a remainder that only reaches rho = 0 is still the best continuation in flight,
        # and the remainders stay the plans 0.2 made (the offline planners refuse such a task up front)
        config = dataclasses.replace(self.planner_config, intervals=intervals, robot_degree=self.degree,
                                     solver_options=budget, refine_nodes=cfg.refine_nodes,
                                     refine_time_s=budget.time_limit_s, warm_start=warm,
                                     diagnose_infeasibility=False, min_robustness_m=0.0)
        start = time.perf_counter()
        try:
            try:
                remainder = plan_spatially_robust(derived, config)
            except InfeasiblePlanError:
                # the task outranks the end states: late in the mission, going home (or the object's rest at
                # tf) can be what makes the rest infeasible; try once more without them
                record.status = "relaxed end states"
                remainder = plan_spatially_robust(_without_end_states(derived), config)
        except PlanTimeoutError:
            record.solve_s = time.perf_counter() - start
            if record.solve_s >= cfg.solver_options.time_limit_s * 0.99:
                self.timeouts += 1
                record.status = "kept: time limit (safety net)"
            else:
                record.status = "kept: no plan within the node budget"
            return None
        except PlannerError as exc:
            record.solve_s = time.perf_counter() - start
            record.status = f"kept: {type(exc).__name__}"
            return None
        record.solve_s = time.perf_counter() - start
        if remainder.stats.get("refine_status") == "time_limit":
            self.timeouts += 1
            record.status = "kept: time limit (safety net)"
            return None
        record.new_robustness = remainder.robustness
        if remainder.robustness <= predicted:
            record.status = "kept: no better than the current plan"
            return None
        spliced, done = splice(plan, remainder, t)
        switches = [] if cfg.allow_side_switches else unflyable_side_switches(spliced, self.scenario, t)
        if switches:
            record.status = "kept: side switch (" + "; ".join(
                f"{sw.robot} round {sw.object} between {sw.t1_s:.1f} and {sw.t2_s:.1f} s" for sw in switches) + ")"
            return None
        record.status = "accepted" + (" (end states relaxed)" if record.status == "relaxed end states" else "")
        record.impacts_added = len(remainder.impacts) - sum(1 for i in plan.impacts if i.time_s > t)
        self.plan_robustness = remainder.robustness
        return spliced, done

    def report(self) -> dict[str, Any]:
        return {"checks": self.checks, "replans": sum(r.status.startswith("accepted") for r in self.records),
                "attempts": len(self.records), "timeouts": self.timeouts, "unreachable": self.unreachable,
                "records": [dataclasses.asdict(r) for r in self.records]}


__all__ = ["MissionConfig", "MissionPlanner", "ReplanRecord", "SideSwitch", "resample_plan", "side_switches", "splice",
           "unflyable_side_switches"]
