"""The spatially robust offline planner (paper Sec. IV-A, IV-B and V) as a MILP over Bezier curves.

    plan = plan_spatially_robust(load_scenario("corridor"))

Maximises the STL spatial robustness rho of the scenario's task subject to satisfying it (each conjunct's
robustness at least ``PlannerConfig.min_robustness_m``, 0.1 mm), the point-mass impact law in real velocities,
conditional smoothness, velocity bounds, thrust limits, robot separation and obstacle clearance. The model is
solved by an open-source solver (HiGHS by default); a second stage keeps rho and trims impacts and
acceleration, and a third fixes the binaries and polishes (``planners/offline/stages.py``, shared with the
impact-robust planner). See ``planners/offline/milp/`` for
each constraint family.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from functools import partial

import numpy as np

from impact_env.transport.scenario import Scenario
from planners.errors import PlannerError
from planners.offline.common import DEFAULT_DEGREE, DEFAULT_INTERVALS, add_obstacle_clearance, check_common_options
from planners.offline.common import encode_task as _encode_task
from planners.offline.config import PlannerConfig
from planners.offline.milp.collisions import add_robot_object_separation, add_robot_separation
from planners.offline.milp.contact_room import add_point_contact_room
from planners.offline.milp.impacts import ImpactVars, add_impacts
from planners.offline.milp.model import LinExpr, Model
from planners.offline.milp.stl_encoding import STLEncoder
from planners.offline.milp.trajectories import (
    Grid,
    ObjectTrajectory,
    RobotTrajectory,
    acceleration_l1,
    add_kinematics,
    allowed_box,
    value,
)
from planners.offline.solvers import lp_optimum
from planners.offline.stages import StagedModel, solve_to_plan
from planners.plan import BodyPlan, Plan, PlannedImpact, Segment
from planners.plan.contact_room import obstacle_bounds

__all__ = ["DEFAULT_DEGREE", "DEFAULT_INTERVALS", "BuiltModel", "PlannerConfig", "build_model", "extract_plan",
           "plan_spatially_robust"]

@dataclass
class BuiltModel:
    """The MILP with handles on its variables, for solving and for reading a solution back."""

    model: Model
    grid: Grid
    robots: list[RobotTrajectory]
    objects: list[ObjectTrajectory]
    impacts: ImpactVars
    rho: LinExpr
    primary: LinExpr
    """What stage 1 maximises and later stages keep: rho, plus the objects' conjuncts' own robustness times
    ``PlannerConfig.conjunct_weight`` when it is > 0."""
    acceleration_cost: LinExpr
    build_time_s: float
    conjunct_groups: list[str] = field(default_factory=list)


def build_model(scenario: Scenario, config: PlannerConfig) -> BuiltModel:
    """Build the MILP of the spatially robust planner (no solving)."""
    start = time.perf_counter()
    grid, degree = check_common_options(scenario, config)
    n = grid.intervals
    model = Model(name=f"sr:{scenario.name}")
    boxes = {b.name: allowed_box(scenario, b) for b in scenario.bodies}
    robots = [RobotTrajectory(model, b, grid, degree, boxes[b.name]) for b in scenario.robots]
    objects = [ObjectTrajectory(model, b, grid, boxes[b.name]) for b in scenario.objects]
    add_kinematics(model, robots, objects, config.thrust_fraction)
    impacts = add_impacts(model, robots, objects, scenario.restitution, scenario.world_box)
    separation = add_robot_separation(model, robots, scenario.world_box)
    if config.robot_object_separation:
        add_robot_object_separation(model, robots, objects, impacts, scenario.world_box, separation)
    if config.contact_cones is not None:
        add_point_contact_room(model, robots, objects, impacts, scenario.world_box, config.contact_cones,
                               [obstacle_bounds(ob) for ob in scenario.obstacles])

    trajectories = {t.spec.name: t for t in robots + objects}
    encoder = STLEncoder(model, grid, lambda body, k: trajectories[body].points(k), boxes, scenario.region_map(),
                         bound_propagation=config.bound_propagation, lp_optimum=lp_optimum)
    if config.obstacle_clearance:
        add_obstacle_clearance(encoder, scenario, n)
    # rho <= every conjunct's robustness: its upper bound is the smallest of theirs
    task = _encode_task(model, encoder, scenario, rho=lambda encoded: model.add_var(
        -encoder.bound, max(-encoder.bound, min(encoder.upper_bound(r) for r in encoded)), name="rho"),
        min_robustness_m=config.min_robustness_m)
    rho = task.rho
    if rho is None:  # encode_task makes it from the callable
        raise PlannerError("the task's robustness variable rho was not created")

    cost = acceleration_l1(model, robots)
    n_terms = sum(len(r.acceleration_points(k)) * 2 for r in robots for k in range(n))
    weight = config.acceleration_weight / max(1, n_terms) / _acceleration_scale(robots)
    # fewer impacts among equally robust plans: a touch with no momentum exchange is a valid point-mass
    # "impact" but not something a robot can fly
    n_impacts = sum(impacts.z.values(), LinExpr())
    # the objects' conjuncts' own margins second to rho (PlannerConfig.conjunct_weight); stage 2 keeps the sum
    object_names = {o.name for o in scenario.objects}
    own = [r for c, r in zip(task.conjuncts, task.robustness) if c.bodies() & object_names]
    primary = rho + sum(own, LinExpr()) * config.conjunct_weight if config.conjunct_weight and own else rho
    model.set_objective(primary - cost * weight - n_impacts * config.impact_weight, maximize=True)
    return BuiltModel(model, grid, robots, objects, impacts, rho, primary, cost, time.perf_counter() - start,
                      task.groups)


def _acceleration_scale(robots: list[RobotTrajectory]) -> float:
    """The largest acceleration any robot's full thrust gives (m/s^2): normalises acceleration costs."""
    return max(max(r.spec.wrench_limits[:2]) / r.spec.mass_kg for r in robots)


def staged_model(built: BuiltModel) -> StagedModel:
    """What the lexicographic stages need from the spatially robust model."""
    return StagedModel(built.model, built.primary, "robustness", sum(built.impacts.z.values(), LinExpr()),
                       built.acceleration_cost, _acceleration_scale(built.robots),
                       [r.acceleration_points(k) for r in built.robots for k in range(built.grid.intervals)],
                       impacts=built.impacts, grid_dt_s=built.grid.dt_s)


def plan_spatially_robust(scenario: Scenario, config: PlannerConfig | None = None) -> Plan:
    """Find the plan of maximal spatial robustness; see the module docstring.

    Raises:
        InfeasiblePlanError: no plan satisfies the task; ``.groups`` names the conflicting constraint groups.
        PlanTimeoutError: time limit reached; ``.plan`` is the best plan found (or None) and ``.mip_gap``.
        UnsupportedSpecError: the task uses STL the planner cannot encode.
    """
    config = config or PlannerConfig()
    built = build_model(scenario, config)
    return solve_to_plan(staged_model(built), config, scenario, partial(extract_plan, scenario, built),
                         lambda plan: f"best robustness {plan.robustness:.4f} m",
                         warm_start=_warm_start(built, config.warm_start))


def extract_plan(scenario: Scenario, built: BuiltModel, x: np.ndarray, solver: str, solve_time_s: float,
                 mip_gap: float) -> Plan:
    """Read a solution vector back into a :class:`Plan`."""
    grid = built.grid
    bodies: dict[str, BodyPlan] = {}
    for r in built.robots:
        segs = [Segment(*grid.interval(k), np.array([value(p, x) for p in r.points(k)])) for k in range(grid.intervals)]
        bodies[r.spec.name] = BodyPlan(r.spec.name, "robot", segs)
    for o in built.objects:
        segs = [Segment(*grid.interval(k), np.array([value(p, x) for p in o.points(k)])) for k in range(grid.intervals)]
        bodies[o.spec.name] = BodyPlan(o.spec.name, "object", segs)
    impacts = []
    robots = {r.spec.name: r for r in built.robots}
    objects = {o.spec.name: o for o in built.objects}
    for (rn, on, k), z in sorted(built.impacts.z.items(), key=lambda item: item[0][2]):
        if z.value(x) > 0.5:
            r, o = robots[rn], objects[on]
            impacts.append(PlannedImpact(
                time_s=grid.knot(k), robot=rn, object=on, position=tuple(value(o.position_at_knot(k), x)),
                object_velocity_before=tuple(value(o.velocity(k - 1), x)),
                object_velocity_after=tuple(value(o.velocity(k), x)),
                robot_velocity_before=tuple(value(r.velocity_end(k - 1), x)),
                robot_velocity_after=tuple(value(r.velocity_start(k), x))))
    m = built.model
    stats = {"intervals": grid.intervals, "robot_degree": built.robots[0].degree, "binaries": m.n_binaries,
             "variables": m.n_vars, "rows": m.n_rows}
    return Plan(scenario=scenario.name, planner="sr", robustness=float(built.rho.value(x)), bodies=bodies,
                impacts=impacts, solver=solver, solve_time_s=solve_time_s, build_time_s=built.build_time_s,
                mip_gap=float(mip_gap), stats=stats)


def _warm_start(built: BuiltModel, plan: Plan | None) -> np.ndarray | None:
    """A partial start vector (NaN where unknown) from a previous plan on the same grid and degree."""
    if plan is None:
        return None
    x = np.full(built.model.n_vars, np.nan)
    for r in built.robots:
        bp = plan.bodies.get(r.spec.name)
        if bp is None or len(bp.segments) != built.grid.intervals or len(bp.segments[0].control_points) != r.degree + 1:
            return None
        for k, seg in enumerate(bp.segments):
            for p, v in zip(r.points(k), seg.control_points):
                for axis in range(2):
                    (idx,) = p[axis].terms
                    x[idx] = v[axis]
    for o in built.objects:
        bp = plan.bodies.get(o.spec.name)
        if bp is None or len(bp.segments) != built.grid.intervals:
            return None
        for k in range(built.grid.intervals + 1):
            v = bp.segments[min(k, built.grid.intervals - 1)].control_points[0 if k < built.grid.intervals else -1]
            for axis in range(2):
                (idx,) = o.position_at_knot(k)[axis].terms
                x[idx] = v[axis]
    hits = {(i.robot, i.object, round(i.time_s / built.grid.dt_s)) for i in plan.impacts}
    for key, z in built.impacts.z.items():
        (idx,) = z.terms
        x[idx] = 1.0 if key in hits else 0.0
    return x
