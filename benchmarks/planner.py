"""Planner benchmark: model size, build time and MILP solve time of the spatially robust planner.

For each scenario and each available solver, builds the model once (to time the build and count binaries
and rows), then plans ``--repeats`` times with solver seeds 0, 1, ... (solve times vary ~2x with the seed,
hence the median). "rho solve s" is the stage-1 MILP solve that proves rho optimal
(``Plan.solve_time_s``); "total s" is the median wall time of the whole ``plan_spatially_robust`` call
(build, stage 1, the impact-count refinement cut at 20 nodes, the polish LP, the plan check). Each HiGHS row
is followed, in the same run, by a baseline row: the same model without the robustness bound propagation
(every robustness variable bounded only by the scene's diagonal, as with a global big-M), stage 1 only.
Prints a markdown table. Usage:

    python benchmarks/planner.py [--scenarios a,b,c] [--solvers highs,scip] [--repeats 3] [--time-limit 60]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from dataclasses import dataclass

from impact_env.errors import ImpactEnvError
from impact_env.scenario import load_scenario, scenario_names
from planners.errors import PlanTimeoutError
from planners.offline.solvers import available_solvers
from planners.offline.sr_planner import PlannerConfig, build_model, plan_spatially_robust


@dataclass
class Run:
    """One planner call: MILP solve time (s), whole-call wall time (s), robustness (m), gap, impacts."""

    solve_s: float
    total_s: float
    rho: float
    gap: float
    impacts: int
    timed_out: bool


def plan_once(scenario, solver: str, seed: int, time_limit_s: float, baseline: bool = False) -> Run:
    """Plan with ``solver`` and ``seed``; a time-out with a plan counts (flagged), without one it raises."""
    config = PlannerConfig(solver=solver, seed=seed, time_limit_s=time_limit_s)
    if baseline:
        config.bound_propagation, config.refine_time_s = False, 0.0
    start = time.perf_counter()
    timed_out = False
    try:
        plan = plan_spatially_robust(scenario, config)
    except PlanTimeoutError as exc:
        if exc.plan is None:
            raise
        plan, timed_out = exc.plan, True
    total = time.perf_counter() - start
    return Run(plan.solve_time_s, total, plan.robustness, plan.mip_gap, len(plan.impacts), timed_out)


def spread(values: list[float]) -> str:
    """``median (min-max)`` with two decimals."""
    return f"{statistics.median(values):.2f} ({min(values):.2f}-{max(values):.2f})"


def row(scenario_name: str, solver: str, repeats: int, time_limit_s: float, baseline: bool = False) -> str:
    """One markdown table row for a scenario and a solver."""
    scenario = load_scenario(scenario_name)
    built = build_model(scenario, PlannerConfig(solver=solver))
    m = built.model
    label = f"{solver}, baseline: no bound propagation" if baseline else solver
    head = f"| {scenario_name} | {label} | {m.n_binaries} | {m.n_rows} | {built.build_time_s:.3f} |"
    try:
        runs = [plan_once(scenario, solver, seed, time_limit_s, baseline) for seed in range(repeats)]
    except ImpactEnvError as exc:  # infeasible, no plan within the limit, unsupported spec, ...
        return f"{head} {type(exc).__name__}: {str(exc).splitlines()[0]} | | | | |"
    rhos = sorted({f"{r.rho:.4f}" for r in runs})
    gaps = max(r.gap for r in runs)
    timeouts = sum(r.timed_out for r in runs)
    note = f" ({timeouts} time-outs)" if timeouts else ""
    impacts = sorted({r.impacts for r in runs})
    return (f"{head} {spread([r.solve_s for r in runs])}{note} | {spread([r.total_s for r in runs])} | "
            f"{' / '.join(rhos)} | {100 * gaps:.2f}% | {' / '.join(map(str, impacts))} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenarios", default=",".join(scenario_names()), help="comma-separated (default: all)")
    parser.add_argument("--solvers", default="highs,scip,gurobi", help="comma-separated; unavailable ones skipped")
    parser.add_argument("--repeats", type=int, default=3, help="solves per scenario and solver (seeds 0..n-1)")
    parser.add_argument("--time-limit", type=float, default=60.0, help="solver time limit per solve (s)")
    args = parser.parse_args()
    if args.repeats < 1:
        parser.error(f"--repeats must be >= 1, got {args.repeats}")

    available = set(available_solvers())
    requested = [s for s in args.solvers.split(",") if s]
    solvers = [s for s in requested if s in available]
    skipped = [s for s in requested if s not in available]
    if skipped:
        print(f"skipped (not installed): {', '.join(skipped)}\n")
    if not solvers:
        raise SystemExit(f"none of the requested solvers is available (available: {', '.join(sorted(available))})")

    print(f"{args.repeats} solves per row (seeds 0..{args.repeats - 1}), time limit {args.time_limit:g} s; "
          "times as median (min-max); rho and impacts list every distinct value, gap is the largest\n")
    print("| scenario | solver | binaries | rows | build s | rho solve s | total s | rho (m) | gap | impacts |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for name in [s for s in args.scenarios.split(",") if s]:
        for solver in solvers:
            print(row(name, solver, args.repeats, args.time_limit), flush=True)
            if solver == "highs":
                print(row(name, solver, args.repeats, args.time_limit, baseline=True), flush=True)
    print(f"\nmachine: {os.cpu_count()} CPUs (os.cpu_count()); solver threads left at the solver's default")


if __name__ == "__main__":
    main()
