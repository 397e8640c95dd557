"""The spatially robust offline planner (paper Sec. IV-A, IV-B and V) as a MILP over Bezier curves.

    plan = plan_spatially_robust(load_scenario("corridor"))

Maximises the STL spatial robustness rho of the scenario's task subject to satisfying it (rho >= 0), the
point-mass impact law in real velocities, conditional smoothness, velocity bounds, thrust limits, robot
separation and obstacle clearance. The model is solved by an open-source solver (HiGHS by default); a
second stage fixes the binaries and smooths the robots' accelerations with a convex QP (Eq. 28) while
keeping rho. See ``planners/offline/milp/`` for each constraint family.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from impact_env.scenario import Scenario
from planners.errors import PlannerError, PlanTimeoutError
from planners.offline.milp.collisions import add_robot_object_separation, add_robot_separation
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
from planners.offline.solvers import solve
from planners.offline.solvers.base import Progress, SolverOptions, Status
from planners.plan import BodyPlan, Plan, PlannedImpact, Segment

DEFAULT_INTERVALS = 10
DEFAULT_DEGREE = 4


@dataclass
class PlannerConfig:
    """Options of the spatially robust planner.

    The solve is lexicographic: (1) maximise rho; (2) with rho kept, minimise the number of impacts plus
    the L1 acceleration (Eq. 28), warm-started, for at most ``refine_nodes`` branch-and-bound nodes (0 skips
    it, None: no limit; ``refine_time_s`` is only a safety net); (3) with the
    binaries fixed, an LP with the stage-2 objective, or with ``smooth`` a convex QP minimising squared
    accelerations (Eq. 28). The QP is off by default: HiGHS's QP solver takes 1-30 s on these models, 10x
    the MILP, and stage 2 already minimises the L1 acceleration.

    Stage 2 rarely proves its optimum quickly (obstacle_avoidance: gap 0.68 after 60 s), so it must be cut
    short. It is cut by a node count, not by time. Under the former 5 s time limit the incumbent it
    stopped at, and so the plan the expert flies, depended on how busy the machine was: obstacle_avoidance
    came out with a different plan with every core busy, and the corridor's stage 2 needs 4.5 s of the 5 s
    when the machine is idle. A node limit is the same work on every machine, so the same scenario and
    config give the same plan. On all three scenarios the incumbent after 20 nodes is as good as the best
    one found in 60 s (``benchmarks/planner_stage2.py``).

    intervals / robot_degree: the time grid and the robots' curve degree (default: the scenario's
    ``[planner]`` hints, else 10 and 4). thrust_fraction: share of each robot's thrust limit the plan may
    use (the rest is the controller's margin). robot_object_separation: keep robots' discs off objects'
    discs except on the intervals next to their impacts (off by default, as in the paper: it is
    conservative over whole intervals, can make short tasks infeasible, and costs ~10x solve time; the
    controller keeps robots off objects instead). acceleration_weight: the L1 acceleration cost is scaled so
    that it can move rho by at most this many metres in stage 1 (a tie-break below the MIP gap).
    impact_weight: the same for the impact count. smooth: run the QP smoothing stage. solver,
    time_limit_s, mip_gap, threads, verbose, seed, progress: passed to the solver. node_limit:
    branch-and-bound nodes of the robustness stage (None: no limit; the mission replanner's budget).
    warm_start: a previous plan on the same grid to start from. bound_propagation: give every robustness
    variable its exact upper bound (off only to measure what it buys, see benchmarks/planner.py).
    """

    intervals: int | None = None
    robot_degree: int | None = None
    thrust_fraction: float = 0.5
    acceleration_weight: float = 1e-6
    impact_weight: float = 1e-6
    refine_nodes: int | None = 20
    refine_time_s: float = 60.0
    smooth: bool = False
    obstacle_clearance: bool = True
    robot_object_separation: bool = False
    solver: str = "highs"
    time_limit_s: float | None = 60.0
    node_limit: int | None = None
    mip_gap: float = 1e-4
    threads: int | None = None
    verbose: bool = False
    seed: int = 0
    progress: Callable[[Progress], None] | None = None
    warm_start: Plan | None = None
    diagnose_infeasibility: bool = True
    bound_propagation: bool = True


@dataclass
class BuiltModel:
    """The MILP with handles on its variables, for solving and for reading a solution back."""

    model: Model
    grid: Grid
    robots: list[RobotTrajectory]
    objects: list[ObjectTrajectory]
    impacts: ImpactVars
    rho: LinExpr
    acceleration_cost: LinExpr
    build_time_s: float
    conjunct_groups: list[str] = field(default_factory=list)


def build_model(scenario: Scenario, config: PlannerConfig) -> BuiltModel:
    """Build the MILP of the spatially robust planner (no solving)."""
    start = time.perf_counter()
    if not scenario.objects:
        raise PlannerError(f"scenario {scenario.name!r} has no object to transport")
    if not 0.0 < config.thrust_fraction <= 1.0:
        raise PlannerError(f"thrust_fraction must be in (0, 1], got {config.thrust_fraction}")
    if config.refine_nodes is not None and config.refine_nodes < 0:
        raise PlannerError(f"refine_nodes must be >= 0 (0 skips stage 2) or None (no node limit), "
                           f"got {config.refine_nodes}")
    n = config.intervals or scenario.planner_intervals or DEFAULT_INTERVALS
    degree = config.robot_degree or scenario.planner_robot_degree or DEFAULT_DEGREE
    if n < 2 or degree < 2:
        raise PlannerError(f"need at least 2 intervals and robot degree >= 2, got {n} and {degree}")
    grid = Grid(n, scenario.tf_s)
    model = Model(name=f"sr:{scenario.name}")
    boxes = {b.name: allowed_box(scenario, b) for b in scenario.bodies}
    robots = [RobotTrajectory(model, b, grid, degree, boxes[b.name]) for b in scenario.robots]
    objects = [ObjectTrajectory(model, b, grid, boxes[b.name]) for b in scenario.objects]
    add_kinematics(model, robots, objects, config.thrust_fraction)
    impacts = add_impacts(model, robots, objects, scenario.restitution, scenario.world_box)
    separation = add_robot_separation(model, robots, scenario.world_box)
    if config.robot_object_separation:
        add_robot_object_separation(model, robots, objects, impacts, scenario.world_box, separation)

    trajectories = {t.spec.name: t for t in robots + objects}
    encoder = STLEncoder(model, grid, lambda body, k: trajectories[body].points(k), boxes, scenario.region_map(),
                         bound_propagation=config.bound_propagation)
    if config.obstacle_clearance:
        for body in scenario.bodies:
            for obstacle in scenario.obstacles:
                for k in range(n):
                    encoder.clearance(body.name, obstacle.name, k, body.radius_m, group="obstacle clearance")

    # one group per top-level conjunct of the task, so that infeasibility names the conflicting parts
    formula = scenario.formula
    conjuncts = formula.children if type(formula).__name__ == "And" else (formula,)
    encoded = []
    for c in conjuncts:
        encoder.group = f"task: {c}"  # a conjunct's encoding rows live in its own group
        encoded.append(encoder.encode(c))
    # satisfaction (rho >= 0) lives in the conjuncts' own groups, not in a bound, so that an infeasible task
    # is explained by the conjuncts that cause it
    rho = model.add_var(-encoder.bound, max(-encoder.bound, min(encoder.upper_bound(r) for r in encoded)),
                        name="rho")
    groups = []
    for c, r_c in zip(conjuncts, encoded):
        group = f"task: {c}"
        groups.append(group)
        model.add(r_c >= 0.0, group=group)
        model.add(rho <= r_c, group="robustness objective")

    cost = acceleration_l1(model, robots)
    n_terms = sum(len(r.acceleration_points(k)) * 2 for r in robots for k in range(n))
    a_bound = max(max(r.spec.thrust_limit_N) / r.spec.mass_kg for r in robots)
    weight = config.acceleration_weight / max(1, n_terms) / a_bound
    # fewer impacts among equally robust plans: a touch with no momentum exchange is a valid point-mass
    # "impact" but not something a robot can fly
    n_impacts = sum(impacts.z.values(), LinExpr())
    model.set_objective(rho - cost * weight - n_impacts * config.impact_weight, maximize=True)
    return BuiltModel(model, grid, robots, objects, impacts, rho, cost, time.perf_counter() - start, groups)


def plan_spatially_robust(scenario: Scenario, config: PlannerConfig | None = None) -> Plan:
    """Find the plan of maximal spatial robustness; see the module docstring.

    Raises:
        InfeasiblePlanError: no plan satisfies the task; ``.groups`` names the conflicting constraint groups.
        PlanTimeoutError: time limit reached; ``.plan`` is the best plan found (or None) and ``.mip_gap``.
        UnsupportedSpecError: the task uses STL the planner cannot encode.
    """
    config = config or PlannerConfig()
    built = build_model(scenario, config)
    options = SolverOptions(time_limit_s=config.time_limit_s, node_limit=config.node_limit, mip_gap=config.mip_gap,
                            threads=config.threads,
                            verbose=config.verbose, progress=config.progress, seed=config.seed,
                            warm_start=_warm_start(built, config.warm_start))
    result = solve(built.model, config.solver, options)
    if result.status == Status.INFEASIBLE:
        from planners.offline.solvers.diagnose import explain_infeasible

        if config.diagnose_infeasibility:
            # each check is capped: an undecided check keeps its group (a superset is still a true answer)
            raise explain_infeasible(built.model, config.solver, SolverOptions(time_limit_s=2.0))
        from planners.errors import InfeasiblePlanError

        raise InfeasiblePlanError(f"no plan satisfies the task of {scenario.name!r}")
    if result.status in (Status.ERROR, Status.UNBOUNDED):
        raise PlannerError(f"solver {config.solver} failed on {scenario.name!r}: {result.status.value} "
                           f"{result.message}")
    if not result.has_solution:
        raise PlanTimeoutError(f"no plan found within the time limit of {config.time_limit_s} s "
                               f"(try a longer --time-limit or fewer intervals)")
    x = result.x
    refine: dict[str, Any] = {"refine_status": "skipped"}
    if result.status == Status.OPTIMAL and config.refine_nodes != 0 and config.refine_time_s > 0:
        x, refine = _refine(built, x, config)
    t0 = time.perf_counter()
    x = _polish(built, x, config)
    plan = extract_plan(scenario, built, x, result.solver, result.solve_time_s, result.mip_gap or 0.0)
    plan.stats.update(refine, polish_s=time.perf_counter() - t0)
    plan.check(scenario, tol=1e-6)
    if result.status == Status.TIME_LIMIT:
        raise PlanTimeoutError(f"time limit of {config.time_limit_s} s reached with gap {result.mip_gap:.3g}; "
                               f"best robustness {plan.robustness:.4f} m", plan=plan, mip_gap=result.mip_gap)
    return plan


def _copy(m: Model, name: str, integer: bool = True) -> Model:
    integrality = list(m.integer) if integer else [False] * m.n_vars
    return Model(m.name + ":" + name, list(m.col_lo), list(m.col_hi), integrality,
                 m.col_names, list(m.rows), list(m.row_groups))


def _refine(built: BuiltModel, x: np.ndarray, config: PlannerConfig) -> tuple[np.ndarray, dict[str, Any]]:
    """Stage 2: keep rho, minimise impacts + L1 acceleration. Returns the better of x and the new incumbent,
    and stats: solve time, the stage-2 objective of what is returned, and how the solve ended
    (``node_limit`` is the normal, deterministic end; ``time_limit`` means the safety net cut it and the
    plan may differ from run to run)."""
    m = _copy(built.model, "refine")
    m.add(built.rho >= built.rho.value(x) - 1e-7, group="keep robustness")
    n_impacts = sum(built.impacts.z.values(), LinExpr())
    a_bound = max(max(r.spec.thrust_limit_N) / r.spec.mass_kg for r in built.robots)
    n_terms = max(1, len(built.acceleration_cost.terms))
    # one impact outweighs any change in total acceleration
    m.set_objective(n_impacts + built.acceleration_cost * (0.5 / (n_terms * a_bound)), maximize=False)
    options = SolverOptions(time_limit_s=config.refine_time_s, node_limit=config.refine_nodes, mip_gap=1e-3,
                            threads=config.threads, verbose=config.verbose, seed=config.seed, warm_start=x)
    result = solve(m, config.solver, options)
    stopped = (Status.OPTIMAL, Status.NODE_LIMIT, Status.TIME_LIMIT)
    if result.x is not None and result.status in stopped and not m.check(result.x, 1e-5):
        x = result.x
    return x, {"refine_s": result.solve_time_s, "refine_status": result.status.value,
               "refine_objective": float(m.objective.value(x))}


def _polish(built: BuiltModel, x: np.ndarray, config: PlannerConfig) -> np.ndarray:
    """Second stage: binaries fixed exactly, rho kept, then minimise squared accelerations (Eq. 28) if
    ``config.smooth`` (a convex QP), else the same linear objective (an LP). Fixing the binaries also
    removes the integrality tolerance's leak through big-M rows, so the impact law holds to the LP
    tolerance. Falls back to ``x`` if the second stage fails."""
    m = built.model
    fixed = _copy(m, "polish", integer=False)
    for i, is_int in enumerate(m.integer):
        if is_int:
            fixed.col_lo[i] = fixed.col_hi[i] = float(round(x[i]))
    rho = built.rho.value(x)
    fixed.add(built.rho >= rho - 1e-7, group="keep robustness")
    if config.smooth:
        fixed.set_objective(LinExpr(), maximize=False)
        for r in built.robots:
            for k in range(built.grid.intervals):
                for p in r.acceleration_points(k):
                    for axis in range(2):
                        fixed.add_quadratic(p[axis], 1.0)
    else:
        fixed.set_objective(built.acceleration_cost, maximize=False)
    result = solve(fixed, "highs", SolverOptions(time_limit_s=config.time_limit_s, verbose=config.verbose))
    if result.status == Status.OPTIMAL and result.x is not None:
        return result.x
    return x


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
