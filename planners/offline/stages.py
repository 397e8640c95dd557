"""The lexicographic solve shared by the spatially robust and the impact-robust planners.

Both planners maximise one quantity (rho, the STL spatial robustness, or delta, the tolerated post-impact
velocity error) and then, keeping it, prefer plans with fewer impacts and less acceleration:

1. stage 1: maximise the primary quantity, to proven optimality or to ``solver_options.node_limit`` nodes
   (the offline planners' default budget and the mission replanner's; stage 2 then runs only if it proved
   optimality), with a time limit as a safety net;
2. stage 2: keep it (>= its optimum - 1e-7), minimise the number of impacts plus the L1 acceleration
   (Eq. 28), warm-started from stage 1, cut after ``refine_nodes`` branch-and-bound nodes: the same work on
   every machine, so the same plan however busy the machine is (``docs/planner_design.md#lexicographic-stages``);
3. polish: the binaries fixed, an LP with the stage-2 objective (or, with ``smooth``, a convex QP on squared
   accelerations), which also removes the integrality tolerance's leak through big-M rows.

A planner hands its model over as a :class:`StagedModel`; :func:`solve_to_plan` runs the stages and ends the
planner the same way for both (read the plan back, check it and its hand-overs, report a time limit). A plan
whose robot has too little time to get round an object between two impacts (:mod:`planners.plan.handover`)
or on its way to its first impact (:mod:`planners.plan.approach`) is re-solved with that hand-over or
approach cut out (``config.handover``).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from planners.errors import InfeasiblePlanError, PlannerError, PlanTimeoutError, UnflyableHandoverError
from planners.offline.config import PlannerConfig
from planners.offline.milp.impacts import ImpactVars
from planners.offline.milp.model import LinExpr, Model
from planners.offline.solvers import solve
from planners.offline.solvers.base import SolveResult, SolverOptions, Status
from planners.plan.approach import Approach, approaches
from planners.plan.handover import Handover, handovers

if TYPE_CHECKING:
    from impact_env.transport.scenario import Scenario
    from planners.plan import Plan

HANDOVER_GROUP = "hand-over flyability"  # the constraint group of the cuts (named by an infeasibility diagnosis)
# (an approach's cut joins the same group: one test, one margin, one repair budget)

DIAGNOSE_NODES = 100  # branch-and-bound nodes per check of the infeasibility diagnosis
DIAGNOSE_SAFETY_S = 20.0  # and a time limit per check that only a pathological model reaches


@dataclass
class StagedModel:
    """A planner's MILP with what the stages need.

    primary: the maximised quantity (rho or delta); primary_name: its name in messages and in the
    "keep ..." group; impact_count: the sum of the impact binaries; acceleration_cost: the L1 acceleration
    (m/s^2, summed over control points); acceleration_scale: a bound of one acceleration term, to normalise
    it; acceleration_points: per curve and interval, the acceleration control points (for the QP).
    """

    model: Model
    primary: LinExpr
    primary_name: str
    impact_count: LinExpr
    acceleration_cost: LinExpr
    acceleration_scale: float
    acceleration_points: list[list[tuple[LinExpr, LinExpr]]]
    refine_heuristics: bool = True
    refine_acceleration: bool = True
    impacts: ImpactVars | None = None
    grid_dt_s: float | None = None


@dataclass
class StagedSolution:
    """The polished solution vector, the stage-1 solver result, and the stages' statistics."""

    x: np.ndarray
    result: SolveResult
    stats: dict[str, Any]


def solve_stages(staged: StagedModel, config: PlannerConfig, scenario_name: str,
                 warm_start: np.ndarray | None = None, progress=None) -> StagedSolution:
    """Run stages 1-3; see the module docstring.

    Raises:
        InfeasiblePlanError: stage 1 is infeasible; ``.groups`` names the conflicting constraint groups
            (found by re-solving with groups left out, each check capped at ``DIAGNOSE_NODES`` nodes) if
            ``config.diagnose_infeasibility``.
        PlannerError: the solver failed.
        PlanTimeoutError: stage 1 found no solution within the time limit (with a solution, the caller
            decides: ``result.status`` is ``TIME_LIMIT``).
    """
    options = dataclasses.replace(config.solver_options, warm_start=warm_start, progress=progress)
    result = solve(staged.model, config.solver, options)
    if result.status == Status.INFEASIBLE:
        if config.diagnose_infeasibility:
            from planners.offline.solvers.diagnose import explain_infeasible

            # each check is capped by work, not time (an undecided check keeps its group): under the former
            # 2 s cap, which groups were named depended on how busy the machine was
            raise explain_infeasible(staged.model, config.solver,
                                     SolverOptions(time_limit_s=DIAGNOSE_SAFETY_S, node_limit=DIAGNOSE_NODES))
        raise InfeasiblePlanError(f"infeasible: no plan satisfies the task of {scenario_name!r}")
    if result.status in (Status.ERROR, Status.UNBOUNDED):
        raise PlannerError(f"solver {config.solver} failed on {scenario_name!r}: {result.status.value} "
                           f"{result.message}")
    if result.x is None:  # no solution
        if result.status == Status.NODE_LIMIT:
            raise PlanTimeoutError(f"no plan found within the node budget of {config.solver_options.node_limit} "
                                   f"nodes (try a larger --node-limit or fewer intervals)")
        raise PlanTimeoutError(f"no plan found within the time limit of {config.solver_options.time_limit_s} s "
                               f"(try a longer --time-limit or fewer intervals)")
    x = result.x
    stats: dict[str, Any] = {"refine_status": "skipped", "stage1_status": result.status.value,
                             "stage1_nodes": result.nodes}
    if result.status == Status.OPTIMAL and config.refine_nodes != 0 and config.refine_time_s > 0:
        x, refine_stats = refine(staged, x, config)
        stats.update(refine_stats)
    t0 = time.perf_counter()
    x = polish(staged, x, config)
    stats["polish_s"] = time.perf_counter() - t0
    return StagedSolution(x, result, stats)


def solve_to_plan(staged: StagedModel, config: PlannerConfig, scenario: Scenario,
                  extract: Callable[[np.ndarray, str, float, float], Plan], best: Callable[[Plan], str],
                  warm_start: np.ndarray | None = None) -> Plan:
    """Run the stages (:func:`solve_stages`, reporting to ``config.solver_options.progress``) and end a planner
    with their answer: ``extract(x, solver, solve_time_s, mip_gap)`` reads the plan back, its stages'
    statistics join its stats, and it is checked against the scenario (:meth:`Plan.check`, 1e-6) and for its
    hand-overs and its robots' approaches to their first impacts (``config.handover``, one margin for both):
    one with too little time is cut out of the model (:func:`cut_handover`, :func:`cut_approach`) and the
    stages run again, up to ``config.handover.repairs`` times in all. ``plan.stats["handovers"]`` and
    ``["approaches"]`` list the plan's hand-overs and the approaches that must get round their object,
    ``plan.stats["handovers_cut"]`` and ``["approaches_cut"]`` what was cut (each robot, object, times, least
    time needed and time there is); the repaired plan is optimal among the plans without those.

    Raises what :func:`solve_stages` raises; UnflyableHandoverError when a hand-over or an approach is still
    too short after the repairs, or no plan without the cut ones satisfies the task; and PlanTimeoutError when
    the time limit cut stage 1 after it found a plan: ``.plan`` is that plan, ``.mip_gap`` its gap, and the
    message ends with ``best(plan)`` (e.g. ``"best robustness 0.1234 m"``).
    """
    handover = config.handover if staged.impacts is not None and staged.grid_dt_s is not None else None
    cut: list[Handover | Approach] = []
    rounds = 0
    while True:
        try:
            solution = solve_stages(staged, config, scenario.name, warm_start=warm_start,
                                    progress=config.solver_options.progress)
        except InfeasiblePlanError as exc:
            if not cut or handover is None:  # (something was cut: handover is set)
                raise
            raise UnflyableHandoverError(
                f"no plan of {scenario.name!r} satisfies the task without a hand-over or an approach its robot "
                f"cannot fly (cut: "
                + "; ".join(h.describe(handover.margin_of(h)) for h in cut) + ")", cut,
                groups=list(dict.fromkeys([*exc.groups, HANDOVER_GROUP]))) from exc
        result = solution.result
        plan = extract(solution.x, result.solver, result.solve_time_s, result.mip_gap or 0.0)
        plan.stats.update(solution.stats)
        plan.check(scenario, tol=1e-6)
        if handover is None:
            break
        found, ways = handovers(plan, scenario), approaches(plan, scenario, handover.later_approaches)
        checks: list[Handover | Approach] = [*found, *ways]
        bad = [h for h in checks if not h.flyable(handover.margin_of(h))]
        if not bad:
            for key, done in (("handovers", found), ("approaches", ways),
                              ("handovers_cut", [h for h in cut if isinstance(h, Handover)]),
                              ("approaches_cut", [a for a in cut if isinstance(a, Approach)])):
                if done:
                    plan.stats[key] = [h.to_dict() for h in done]
            break
        if rounds >= handover.repairs:
            what = "refuses it" if handover.repairs == 0 else f"could not repair it in {handover.repairs} re-solves"
            kinds = " or ".join(k for k, t in (("a hand-over", Handover), ("an approach", Approach))
                                if any(isinstance(h, t) for h in bad))
            raise UnflyableHandoverError(
                f"the plan of {scenario.name!r} has {kinds} its robot cannot fly: "
                + "; ".join(h.describe(handover.margin_of(h)) for h in bad) + f" (HandoverConfig(repairs="
                f"{handover.repairs}) {what})", bad, plan=plan)
        for h in bad:
            if isinstance(h, Handover):
                cut_handover(staged, h)
            else:
                cut_approach(staged, h)
        cut += bad
        rounds += 1
        warm_start = None  # the last solution has the hand-over that is now cut
    if result.status == Status.TIME_LIMIT:
        raise PlanTimeoutError(f"time limit of {config.solver_options.time_limit_s} s reached with gap "
                               f"{result.mip_gap:.3g}; {best(plan)}", plan=plan, mip_gap=result.mip_gap)
    return plan


def cut_handover(staged: StagedModel, handover: Handover) -> None:
    """Exclude ``handover`` from ``staged.model``: its robot may not hit its object at both of its knots unless
    the robot or the object is hit in between (a row of group :data:`HANDOVER_GROUP`). The row cuts every plan
    with that pair of impacts, also one whose velocity changes make no side switch: a flyability test inside
    the MILP would need the product of the two changes."""
    if staged.impacts is None or staged.grid_dt_s is None:
        raise PlannerError("cut_handover needs a model with impact binaries and its grid (StagedModel.impacts and "
                           "grid_dt_s): the spatially robust planner's")
    z, dt = staged.impacts.z, staged.grid_dt_s
    k1, k2 = round(handover.t1_s / dt), round(handover.t2_s / dt)
    row = z[(handover.robot, handover.object, k1)] + z[(handover.robot, handover.object, k2)]
    for (robot, obj, k), hit in z.items():
        if k1 < k < k2 and (robot == handover.robot or obj == handover.object):
            row = row - hit
    staged.model.add(row <= 1, group=HANDOVER_GROUP)


def cut_approach(staged: StagedModel, approach: Approach) -> None:
    """Exclude ``approach`` from ``staged.model``: its robot may not make its first impact on its object at
    that knot with the object's last flight before it starting where it did (at its start, or at the other
    robot's impact at its knot), unless the robot hits something before or the object is hit in between (a
    row of group :data:`HANDOVER_GROUP`). As :func:`cut_handover`, the exact no-good of those knots. A later
    approach (``approach.after``, the robot's previous impact on another object) is cut the same way with that
    impact's binary in the row: the robot may hit something between the two, or the object be hit."""
    if staged.impacts is None or staged.grid_dt_s is None:
        raise PlannerError("cut_approach needs a model with impact binaries and its grid (StagedModel.impacts and "
                           "grid_dt_s): the spatially robust planner's")
    z, dt = staged.impacts.z, staged.grid_dt_s
    k1 = round(approach.t1_s / dt)
    k0 = -1 if approach.by is None else round(approach.t0_s / dt)
    row = z[(approach.robot, approach.object, k1)]
    ones = 0
    if approach.by is not None:
        row = row + z[(approach.by, approach.object, k0)]
        ones += 1
    kr = -1
    if approach.after is not None:
        kr = round(approach.after.time_s / dt)
        row = row + z[(approach.robot, approach.after.object, kr)]
        ones += 1
    for (robot, obj, k), hit in z.items():
        if kr < k < k1 and (robot == approach.robot or (obj == approach.object and k > k0)):
            row = row - hit
    staged.model.add(row <= ones, group=HANDOVER_GROUP)


def copy_model(m: Model, name: str, integer: bool = True) -> Model:
    """A copy of ``m`` that can take more rows (``integer=False``: every variable continuous)."""
    integrality = list(m.integer) if integer else [False] * m.n_vars
    return Model(m.name + ":" + name, list(m.col_lo), list(m.col_hi), integrality,
                 m.col_names, list(m.rows), list(m.row_groups))


def _stage2_objective(staged: StagedModel) -> LinExpr:
    if not staged.refine_acceleration:
        return staged.impact_count
    n_terms = max(1, len(staged.acceleration_cost.terms))
    # one impact outweighs any change in total acceleration
    return staged.impact_count + staged.acceleration_cost * (0.5 / (n_terms * staged.acceleration_scale))


def refine(staged: StagedModel, x: np.ndarray, config: PlannerConfig) -> tuple[np.ndarray, dict[str, Any]]:
    """Stage 2: keep the primary quantity, minimise impacts + L1 acceleration. Returns the better of x and the
    new incumbent, and stats: solve time, the stage-2 objective of what is returned, and how the solve ended
    (``node_limit`` is the normal, deterministic end; ``time_limit`` means the safety net cut it and the
    plan may differ from run to run)."""
    m = copy_model(staged.model, "refine")
    m.add(staged.primary >= staged.primary.value(x) - 1e-7, group=f"keep {staged.primary_name}")
    m.set_objective(_stage2_objective(staged), maximize=False)
    budget = config.solver_options
    options = SolverOptions(time_limit_s=config.refine_time_s, node_limit=config.refine_nodes, mip_gap=1e-3,
                            threads=budget.threads, verbose=budget.verbose, seed=budget.seed,
                            warm_start=x if config.refine_warm_start else None,
                            heuristics=staged.refine_heuristics)
    result = solve(m, config.solver, options)
    stopped = (Status.OPTIMAL, Status.NODE_LIMIT, Status.TIME_LIMIT)
    if result.x is not None and result.status in stopped and not m.check(result.x, 1e-5):
        # warm, its incumbent is never worse than x; cold, it may be (cut before it found a better one)
        if config.refine_warm_start or m.objective.value(result.x) < m.objective.value(x):
            x = result.x
    return x, {"refine_s": result.solve_time_s, "refine_status": result.status.value,
               "refine_objective": float(m.objective.value(x)), "refine_nodes_explored": result.nodes}


def polish(staged: StagedModel, x: np.ndarray, config: PlannerConfig) -> np.ndarray:
    """Stage 3: binaries fixed exactly, the primary quantity kept, then minimise squared accelerations
    (Eq. 28) if ``config.smooth`` (a convex QP), else the stage-2 objective's acceleration (an LP). Fixing the
    binaries also removes the integrality tolerance's leak through big-M rows, so the impact law holds to
    the LP tolerance. Falls back to ``x`` if the stage fails."""
    m = staged.model
    fixed = copy_model(m, "polish", integer=False)
    for i, is_int in enumerate(m.integer):
        if is_int:
            fixed.col_lo[i] = fixed.col_hi[i] = float(round(x[i]))
    fixed.add(staged.primary >= staged.primary.value(x) - 1e-7, group=f"keep {staged.primary_name}")
    if config.smooth:
        fixed.set_objective(LinExpr(), maximize=False)
        for points in staged.acceleration_points:
            for p in points:
                for axis in range(2):
                    fixed.add_quadratic(p[axis], 1.0)
    else:
        fixed.set_objective(staged.acceleration_cost, maximize=False)
    result = solve(fixed, "highs", SolverOptions(time_limit_s=config.solver_options.time_limit_s,
                                                 verbose=config.solver_options.verbose))
    if result.status == Status.OPTIMAL and result.x is not None:
        return result.x
    return x
