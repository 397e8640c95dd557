"""Planner benchmark: model size, build time and MILP solve time of the spatially robust (SR) and the
impact-robust (IR) planners.

For each scenario, planner and available solver, builds the model once (to time the build and count
binaries and rows), then plans ``--repeats`` times with solver seeds 0, 1, ... (solve times vary ~2x with
the seed, hence the median). The stage-1 column is the MILP solve that proves the planner's objective
optimal (rho for SR, delta for IR; ``Plan.solve_time_s``); "total s" is the median wall time of the whole
planner call (build, stage 1, the refinement cut at 20 nodes, the polish LP, the plan check) and "cpu s" its
process CPU time, which a busy machine inflates less. Each HiGHS row is followed, in the same run, by a
baseline row: for SR the same model without the robustness bound propagation (stage 1 only); for IR the
same model with the box resets switched by big-M rows instead of their convex hull (stage 1 only).

Rows go to ``--cache`` (JSON lines, one cell per row, the file rewritten atomically as each finishes, so a kill
leaves the rows done so far), and a rerun with the same cache prints cached rows instead of solving again
(delete the file to measure afresh). Prints markdown tables. Usage:

    python -m benchmarks.planner [--planners sr,ir] [--scenarios a,b] [--solvers highs,scip] [--repeats 3]
                                 [--time-limit 60] [--cache planner_bench.jsonl]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import resource
import statistics
import time
from dataclasses import dataclass

from impact_env.errors import ImpactEnvError
from impact_env.results_store import CellStore
from impact_env.transport.scenario import load_scenario, scenario_names
from planners.errors import PlanTimeoutError
from planners.offline.impact_robust import IRPlannerConfig, build_ir_model, plan_impact_robust
from planners.offline.solvers import available_solvers
from planners.offline.solvers.base import SolverOptions
from planners.offline.spatially_robust import PlannerConfig, build_model, plan_spatially_robust


@dataclass
class Run:
    """One planner call: stage-1 solve time (s), whole-call wall and CPU time (s), the objective (rho in m or
    delta in m/s), gap, impacts, whether stage 1 hit its time limit."""

    solve_s: float
    total_s: float
    cpu_s: float
    objective: float
    gap: float
    impacts: int
    timed_out: bool


def _cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def plan_once(scenario, planner: str, solver: str, seed: int, time_limit_s: float, baseline: bool = False) -> Run:
    """Plan with ``solver`` and ``seed``; a time-out with a plan counts (flagged), without one it raises."""
    if planner == "ir":
        config = IRPlannerConfig(solver=solver, solver_options=SolverOptions(seed=seed, time_limit_s=time_limit_s))
        if baseline:
            config = dataclasses.replace(config, disjunctive_resets=False, refine_time_s=0.0)
        plan_fn = plan_impact_robust
    else:
        config = PlannerConfig(solver=solver, solver_options=SolverOptions(seed=seed, time_limit_s=time_limit_s))
        if baseline:
            config = dataclasses.replace(config, bound_propagation=False, refine_time_s=0.0)
        plan_fn = plan_spatially_robust
    start, cpu = time.perf_counter(), _cpu_s()
    timed_out = False
    try:
        plan = plan_fn(scenario, config)
    except PlanTimeoutError as exc:
        if exc.plan is None:
            raise
        plan, timed_out = exc.plan, True
    total, cpu = time.perf_counter() - start, _cpu_s() - cpu
    value = plan.delta_mps if planner == "ir" else plan.robustness
    return Run(plan.solve_time_s, total, cpu, value, plan.mip_gap, len(plan.impacts), timed_out)


def spread(values: list[float]) -> str:
    """``median (min-max)`` with two decimals."""
    return f"{statistics.median(values):.2f} ({min(values):.2f}-{max(values):.2f})"


def row(scenario_name: str, planner: str, solver: str, repeats: int, time_limit_s: float,
        baseline: bool = False) -> str:
    """One markdown table row for a scenario, a planner and a solver."""
    scenario = load_scenario(scenario_name)
    if planner == "ir":
        built = build_ir_model(scenario, IRPlannerConfig(solver=solver, disjunctive_resets=not baseline))
        label = f"{solver}, baseline: big-M resets" if baseline else solver
    else:
        built = build_model(scenario, PlannerConfig(solver=solver))
        label = f"{solver}, baseline: no bound propagation" if baseline else solver
    m = built.model
    head = f"| {scenario_name} | {label} | {m.n_binaries} | {m.n_rows} | {built.build_time_s:.3f} |"
    try:
        runs = [plan_once(scenario, planner, solver, seed, time_limit_s, baseline) for seed in range(repeats)]
    except ImpactEnvError as exc:  # infeasible, no plan within the limit, unsupported spec, ...
        return f"{head} {type(exc).__name__}: {str(exc).splitlines()[0]} | | | | | |"
    digits = 5 if planner == "ir" else 4
    values = sorted({f"{r.objective:.{digits}f}" for r in runs})
    gaps = max(r.gap for r in runs)
    timeouts = sum(r.timed_out for r in runs)
    note = f" ({timeouts} time-outs)" if timeouts else ""
    impacts = sorted({r.impacts for r in runs})
    return (f"{head} {spread([r.solve_s for r in runs])}{note} | {spread([r.total_s for r in runs])} | "
            f"{statistics.median(r.cpu_s for r in runs):.1f} | {' / '.join(values)} | {100 * gaps:.2f}% | "
            f"{' / '.join(map(str, impacts))} |")


HEADERS = {
    "sr": ("| scenario | solver | binaries | rows | build s | rho solve s | total s | cpu s | rho (m) | gap | "
           "impacts |\n|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"),
    "ir": ("| scenario | solver | binaries | rows | build s | delta solve s | total s | cpu s | delta (m/s) | gap | "
           "impacts |\n|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"),
}
TITLES = {"sr": "Spatially robust planner (maximise rho)",
          "ir": "Impact-robust planner (maximise delta)"}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--planners", default="sr,ir", help="comma-separated: sr, ir (default both)")
    parser.add_argument("--scenarios", default=",".join(scenario_names()), help="comma-separated (default: all)")
    parser.add_argument("--solvers", default="highs,scip,gurobi", help="comma-separated; unavailable ones skipped")
    parser.add_argument("--repeats", type=int, default=3, help="solves per scenario and solver (seeds 0..n-1)")
    parser.add_argument("--time-limit", type=float, default=60.0, help="solver time limit per solve (s)")
    parser.add_argument("--cache", default=None, help="JSON-lines file of finished rows, reused on a rerun")
    args = parser.parse_args(argv)
    if args.repeats < 1:
        parser.error(f"--repeats must be >= 1, got {args.repeats}")
    planners = [p for p in args.planners.split(",") if p]
    if any(p not in HEADERS for p in planners):
        parser.error(f"--planners takes sr and/or ir, got {args.planners!r}")

    available = set(available_solvers())
    requested = [s for s in args.solvers.split(",") if s]
    solvers = [s for s in requested if s in available]
    skipped = [s for s in requested if s not in available]
    if skipped:
        print(f"skipped (not installed): {', '.join(skipped)}\n")
    if not solvers:
        raise SystemExit(f"none of the requested solvers is available (available: {', '.join(sorted(available))})")

    # one cell per row in a CellStore (rewritten atomically), so a run killed mid-write resumes from its cells
    store = CellStore(args.cache, key=lambda cell: cell["key"]) if args.cache else None
    cache: dict[str, str] = {}

    def cached_row(name: str, planner: str, solver: str, baseline: bool = False) -> str:
        key = json.dumps([name, planner, solver, baseline, args.repeats, args.time_limit])
        if key not in cache and store is not None and key in store:
            cache[key] = store.get(key)["row"]
        if key not in cache:
            cache[key] = row(name, planner, solver, args.repeats, args.time_limit, baseline)
            if store is not None:
                store.put({"key": key, "row": cache[key]})
        return cache[key]

    print(f"{args.repeats} solves per row (seeds 0..{args.repeats - 1}), time limit {args.time_limit:g} s; "
          "times as median (min-max), cpu s the median CPU time of the whole call; objective and impacts list "
          "every distinct value, gap is the largest")
    for planner in planners:
        print(f"\n{TITLES[planner]}\n\n{HEADERS[planner]}")
        for name in [s for s in args.scenarios.split(",") if s]:
            for solver in solvers:
                print(cached_row(name, planner, solver), flush=True)
                if solver == "highs":
                    print(cached_row(name, planner, solver, baseline=True), flush=True)
    print(f"\nmachine: {os.cpu_count()} CPUs (os.cpu_count()), load average {os.getloadavg()[0]:.1f} at the end; "
          "solver threads left at the solver's default")


if __name__ == "__main__":
    main()
