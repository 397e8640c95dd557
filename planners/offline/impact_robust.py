"""The impact-robust offline planner (paper Sec. IV-C, Eq. 16-20, Lemma 1) as a MILP over Bezier curves.

    plan = plan_impact_robust(load_scenario("corridor"))
    plan.delta_mps      # every impact may send the object off up to this far (m/s, per axis) from the plan

Maximises delta, the post-impact velocity error (per axis, at every robot-object impact) that the plan
tolerates: for every such error the task still holds and every object ends inside its final box
(``[final_box]`` in the scenario; default :data:`DEFAULT_FINAL_BOX`). It shares the spatially robust
planner's grid, curves, impact law, STL encoding, solvers and stages. New are the object's state as a
zonotope per axis (``milp/boxes.py``, Eq. 17-19) and each robot as four copies that reach the box's vertices
(``milp/copies.py``, Lemma 1), with affine feedback through the copies. The encoding is exact up to the
interval hull taken at each impact, as in the paper. Why, and how it differs from the paper's code:
``docs/planner_design.md#impact-robust-planner``.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from functools import partial

import numpy as np

from impact_env.transport.scenario import Scenario
from planners.errors import PlannerError
from planners.offline.common import add_obstacle_clearance, check_common_options, encode_task
from planners.offline.config import DEFAULT_COPY_INTERVALS, DEFAULT_FINAL_BOX, IRPlannerConfig, PlannerConfig
from planners.offline.milp.boxes import ObjectBox
from planners.offline.milp.collisions import add_robot_separation
from planners.offline.milp.contact_room import add_contact_room
from planners.offline.milp.copies import SIGNS, RobotCopies, add_copy_impacts
from planners.offline.milp.impacts import ImpactVars, add_object_smoothness, impact_binaries
from planners.offline.milp.model import LinExpr, Model
from planners.offline.milp.stl_encoding import STLEncoder
from planners.offline.milp.trajectories import (
    Grid,
    ObjectTrajectory,
    acceleration_l1,
    add_kinematics,
    allowed_box,
    value,
    velocity_bound,
)
from planners.offline.solvers import lp_optimum
from planners.offline.stages import StagedModel, solve_to_plan
from planners.plan import BodyPlan, ImpactCopies, ObjectFunnel, Plan, PlannedImpact, Segment
from planners.plan.contact_room import obstacle_bounds


@dataclass
class IRModel:
    """The impact-robust MILP with handles on its variables."""

    model: Model
    grid: Grid
    robots: list[RobotCopies]
    objects: list[ObjectTrajectory]
    boxes: list[ObjectBox]
    impacts: ImpactVars
    delta: LinExpr
    acceleration_cost: LinExpr
    build_time_s: float
    final_boxes: dict[str, tuple[tuple[float, float], tuple[float, float]]]
    window: int
    conjunct_groups: list[str] = field(default_factory=list)


def final_boxes(scenario: Scenario, default: tuple[float, float] = DEFAULT_FINAL_BOX
                ) -> dict[str, tuple[tuple[float, float], tuple[float, float]]]:
    """Per object, the (position, velocity) half-widths of its final box: the scenario's or ``default``."""
    out = {}
    for o in scenario.objects:
        box = scenario.final_box(o.name)
        out[o.name] = ((box.position_m, box.velocity_mps) if box is not None
                       else ((default[0],) * 2, (default[1],) * 2))
    return out


def build_ir_model(scenario: Scenario, config: IRPlannerConfig) -> IRModel:
    """Build the MILP of the impact-robust planner (no solving)."""
    start = time.perf_counter()
    grid, degree = check_common_options(scenario, config)
    n = grid.intervals
    model = Model(name=f"ir:{scenario.name}")
    allowed = {b.name: allowed_box(scenario, b) for b in scenario.bodies}
    robots = [RobotCopies(model, b, grid, degree, allowed[b.name]) for b in scenario.robots]
    objects = [ObjectTrajectory(model, b, grid, allowed[b.name]) for b in scenario.objects]
    ends = final_boxes(scenario, config.default_final_box)
    # an impacted object keeps a velocity spread >= delta to the end, which its final box bounds: delta can
    # be no larger (if no object is ever hit any delta is tolerated, and the cap is what is reported)
    delta_ub = max(min(min(velocity_bound(o)), min(ends[o.name][1])) for o in scenario.objects)
    delta = model.add_var(0.0, delta_ub, name="delta")
    model.add(delta >= config.min_delta_mps, group=f"delta >= min_delta_mps = {config.min_delta_mps:g} m/s")
    boxes = [ObjectBox(model, o, allowed[o.spec.name], delta, delta_ub) for o in objects]

    add_kinematics(model, [c for r in robots for c in r.copies], objects, config.thrust_fraction)
    impacts = impact_binaries(model, [r.nominal for r in robots], objects)
    for o in objects:
        add_object_smoothness(model, o, impacts)
    window = config.copy_intervals or scenario.planner_copy_intervals or DEFAULT_COPY_INTERVALS
    if not 1 <= window <= n // 2:
        raise PlannerError(f"copy_intervals must be in 1..{n // 2} (half the grid's {n} intervals), got {window}")
    resets = add_copy_impacts(model, robots, boxes, impacts, scenario.restitution, scenario.world_box, window)
    if config.contact_cones is not None:
        add_contact_room(model, robots, boxes, impacts, scenario.world_box, config.contact_cones,
                         [obstacle_bounds(ob) for ob in scenario.obstacles])
    for box in boxes:
        box.add_propagation(model, impacts, resets[box.spec.name], disjunctive=config.disjunctive_resets)
        box.add_bounds(model)
        box.add_final_box(model, *ends[box.spec.name])
    add_robot_separation(model, robots, scenario.world_box)

    point_sets = {r.spec.name: r.point_sets for r in robots}
    point_sets.update({b.spec.name: b.point_sets for b in boxes})
    encoder = STLEncoder(model, grid, lambda body, k: point_sets[body](k), allowed, scenario.region_map(),
                         bound_propagation=config.bound_propagation, reuse_clearance=True, lp_optimum=lp_optimum)
    if config.obstacle_clearance:
        add_obstacle_clearance(encoder, scenario, n)
    task = encode_task(model, encoder, scenario, min_robustness_m=config.min_robustness_m)

    copies = [c for r in robots for c in r.copies]
    cost = acceleration_l1(model, copies)
    n_terms = max(1, len(cost.terms))
    weight = config.acceleration_weight / n_terms / _acceleration_scale(robots)
    n_impacts = sum(impacts.z.values(), LinExpr())
    model.set_objective(delta - cost * weight - n_impacts * config.impact_weight, maximize=True)
    return IRModel(model, grid, robots, objects, boxes, impacts, delta, cost, time.perf_counter() - start, ends,
                   window, task.groups)


def _acceleration_scale(robots: list[RobotCopies]) -> float:
    return max(max(r.spec.wrench_limits[:2]) / r.spec.mass_kg for r in robots)


def staged_model(built: IRModel) -> StagedModel:
    """What the lexicographic stages need from the impact-robust model."""
    # Stage 2 minimises the impact count alone: with the four copies' L1 acceleration in its objective each
    # node's LP was 5-10x slower (obstacle_avoidance: 70 s for 20 nodes) and it ended with more impacts
    # (6 instead of 4); the polish LP (stage 3) then minimises that acceleration with the binaries fixed.
    return StagedModel(built.model, built.delta, "delta", sum(built.impacts.z.values(), LinExpr()),
                       built.acceleration_cost, _acceleration_scale(built.robots),
                       [r.acceleration_points(k) for r in built.robots for k in range(built.grid.intervals)],
                       refine_acceleration=False, impacts=built.impacts, grid_dt_s=built.grid.dt_s)


def plan_impact_robust(scenario: Scenario, config: IRPlannerConfig | None = None) -> Plan:
    """Find the plan that tolerates the largest post-impact velocity error delta; see the module docstring.

    Raises:
        InfeasiblePlanError: no plan tolerates ``min_delta_mps``; ``.groups`` names the conflicting groups
            (e.g. 'final box' and the delta floor when the final box is smaller than the grid can trim to).
        PlanTimeoutError: time limit reached; ``.plan`` is the best plan found (or None) and ``.mip_gap``.
        UnsupportedSpecError: the task uses STL the planner cannot encode.
    """
    config = config or IRPlannerConfig()
    if not isinstance(config, IRPlannerConfig):
        config = IRPlannerConfig(**{f.name: getattr(config, f.name) for f in dataclasses.fields(PlannerConfig)})
    built = build_ir_model(scenario, config)
    return solve_to_plan(staged_model(built), config, scenario, partial(extract_ir_plan, scenario, built),
                         lambda plan: f"best delta {plan.delta_mps:.5f} m/s")


def _segments(curve, grid: Grid, x: np.ndarray) -> list[Segment]:
    return [Segment(*grid.interval(k), np.array([value(p, x) for p in curve.points(k)]))
            for k in range(grid.intervals)]


def extract_ir_plan(scenario: Scenario, built: IRModel, x: np.ndarray, solver: str, solve_time_s: float,
                    mip_gap: float) -> Plan:
    """Read a solution vector back into a :class:`Plan` with its funnels and robot copies."""
    grid = built.grid
    bodies: dict[str, BodyPlan] = {}
    for r in built.robots:
        bodies[r.spec.name] = BodyPlan(r.spec.name, "robot", _segments(r.nominal, grid, x))
    for o in built.objects:
        bodies[o.spec.name] = BodyPlan(o.spec.name, "object", _segments(o, grid, x))
    robots = {r.spec.name: r for r in built.robots}
    objects = {o.spec.name: o for o in built.objects}
    impacts, copies = [], []
    for (rn, on, k), z in sorted(built.impacts.z.items(), key=lambda item: item[0][2]):
        if z.value(x) <= 0.5:
            continue
        r, o = robots[rn], objects[on]
        impacts.append(PlannedImpact(
            time_s=grid.knot(k), robot=rn, object=on, position=tuple(value(o.position_at_knot(k), x)),
            object_velocity_before=tuple(value(o.velocity(k - 1), x)),
            object_velocity_after=tuple(value(o.velocity(k), x)),
            robot_velocity_before=tuple(value(r.nominal.velocity_end(k - 1), x)),
            robot_velocity_after=tuple(value(r.nominal.velocity_start(k), x))))
        first, last = max(0, k - built.window), min(grid.intervals, k + built.window)
        copies.append(ImpactCopies(
            time_s=grid.knot(k), robot=rn, object=on, window_start_s=grid.knot(first), window_end_s=grid.knot(last),
            signs=list(SIGNS),
            before=[np.array([[value(p, x) for p in c.points(j)] for j in range(first, k)]) for c in r.copies],
            after=[np.array([[value(p, x) for p in c.points(j)] for j in range(k, last)]) for c in r.copies]))
    funnels = {}
    for box in built.boxes:
        name = box.spec.name
        position, velocity = built.final_boxes[name]
        funnels[name] = ObjectFunnel(
            name, grid.knot(0), grid.dt_s,
            position_halfwidth_m=np.array([[h.value(x) for h in hk] for hk in box.hp]),
            velocity_halfwidth_mps=np.array([[h.value(x) for h in hk] for hk in box.hv]),
            final_box_m=position, final_box_mps=velocity)
    m = built.model
    stats = {"intervals": grid.intervals, "robot_degree": built.robots[0].degree, "binaries": m.n_binaries,
             "variables": m.n_vars, "rows": m.n_rows}
    delta = float(built.delta.value(x))
    plan = Plan(scenario=scenario.name, planner="ir", robustness=0.0, bodies=bodies, impacts=impacts,
                solver=solver, solve_time_s=solve_time_s, build_time_s=built.build_time_s, mip_gap=float(mip_gap),
                stats=stats, delta_mps=delta, funnels=funnels, copies=copies)
    # the MILP bounds half-widths from below only: record the exact propagated spread, except for the box
    # the copies were built for at each impact (position at the impact knot, velocity on the interval before)
    from planners.plan.funnels import feedback, propagate

    fb = feedback(plan, scenario)
    for name, funnel in funnels.items():
        hp, hv = propagate(funnel, delta, fb[name])
        at_impact = np.zeros(len(hp), dtype=bool)
        at_impact[list(fb[name])] = True
        funnel.position_halfwidth_m = np.where(at_impact[:, None], funnel.position_halfwidth_m,
                                               np.minimum(funnel.position_halfwidth_m, hp))
        funnel.velocity_halfwidth_mps = np.where(at_impact[1:, None], funnel.velocity_halfwidth_mps,
                                                 np.minimum(funnel.velocity_halfwidth_mps, hv))
    plan.robustness = nominal_robustness(scenario, plan)
    return plan


def nominal_robustness(scenario: Scenario, plan: Plan) -> float:
    """STL robustness (m) of the plan's nominal curves, sampled every control period (the impact-robust
    planner keeps the task satisfied for the whole box but does not maximise this margin)."""
    from impact_env.stl import robustness

    dt = scenario.control_period_s
    steps = round(scenario.formula.horizon_s / dt)
    t = np.arange(steps + 1) * dt
    trace = {name: body.position(t) for name, body in plan.bodies.items()}
    return float(robustness(scenario.formula, trace, scenario.region_map(), dt=dt))
