"""Planner stage 2 (fewest impacts, least L1 acceleration, rho kept): cut by nodes or by time, idle or loaded.

Stage 2 rarely proves its optimum quickly, so it is cut short. This compares, in one run, the default cut
(``refine_nodes=20``, deterministic work) with the cut used before it (a 5 s time limit) and with a long
reference (60 s), each once on an idle machine and once with every core busy (one spinning process per
CPU, started by this script). For each row: how stage 2 ended, its time, its objective (impacts plus the
scaled acceleration term: lower is better) and the plan's fingerprint (``Plan.fingerprint``: equal means
the same curves bit for bit). A cut that is deterministic gives the same fingerprint idle and loaded.
Prints a markdown table.

``--gain`` measures instead what the node cut buys: per scenario stage 1 once (the default budget), then stage 2
from its incumbent (the warm start) cut at 1, 5, 20 (the default) and 100 nodes, and once at 20 nodes without the
warm start (``refine_warm_start=False``). Per row: stage 2's time and nodes, its objective (impacts plus the
scaled acceleration term), the gain over the warm start's own objective (what skipping stage 2 would keep), the
impacts and the fingerprint of the plan after the polish. Usage:

    python -m benchmarks.planner_stage2 [--scenarios a,b,c] [--cuts nodes,time5,time60]
    python -m benchmarks.planner_stage2 --gain [--scenarios a,b,c] [--gain-cuts 1,5,20,100]
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import subprocess
import sys
import time
from contextlib import contextmanager

from impact_env.transport.scenario import load_scenario, scenario_names
from planners.offline.spatially_robust import PlannerConfig, plan_spatially_robust

CUTS = {
    "nodes": ("20 nodes (default)", PlannerConfig()),
    "time5": ("5 s (before)", PlannerConfig(refine_nodes=None, refine_time_s=5.0)),
    "time60": ("60 s (reference)", PlannerConfig(refine_nodes=None, refine_time_s=60.0)),
}


@contextmanager
def busy_cores(n: int):
    """``n`` processes spinning on the CPU for the duration of the block (n = 0: none)."""
    hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)]
    try:
        yield
    finally:
        for hog in hogs:
            hog.kill()
            hog.wait()


def row(scenario_name: str, cut: str, loaded: bool) -> str:
    label, config = CUTS[cut]
    with busy_cores((os.cpu_count() or 1) if loaded else 0):
        plan = plan_spatially_robust(load_scenario(scenario_name), config)
    s = plan.stats
    return (f"| {scenario_name} | {label} | {'all cores busy' if loaded else 'idle'} | {s['refine_status']} | "
            f"{s['refine_s']:.2f} | {s['refine_objective']:.4f} | {len(plan.impacts)} | `{plan.fingerprint()}` |")


GAIN_CUTS = (1, 5, 20, 100)


def gain_rows(scenario_name: str, cuts: tuple[int, ...] = GAIN_CUTS) -> list[str]:
    """Stage 1 once, then stage 2 cut at each of ``cuts`` nodes from its incumbent, and once cold at 20."""
    from planners.offline.solvers import solve
    from planners.offline.spatially_robust import build_model, extract_plan, staged_model
    from planners.offline.stages import _stage2_objective, polish, refine

    scenario = load_scenario(scenario_name)
    config = PlannerConfig()
    built = build_model(scenario, config)
    staged = staged_model(built)
    t0 = time.perf_counter()
    first = solve(staged.model, config.solver, config.solver_options)
    stage1_s = time.perf_counter() - t0
    x0 = first.x
    objective = _stage2_objective(staged)
    start = float(objective.value(x0))

    def row(label: str, x, seconds: float, nodes, status: str) -> str:
        x = polish(staged, x, config)
        plan = extract_plan(scenario, built, x, first.solver, first.solve_time_s, first.mip_gap or 0.0)
        value = float(objective.value(x))
        return (f"| {scenario_name} | {label} | {seconds:.1f} | {nodes if nodes is not None else '-'} | {status} | "
                f"{value:.4f} | {start - value:.4f} | {len(plan.impacts)} | `{plan.fingerprint()}` |")

    rows = [f"| {scenario_name} | stage 1 ({first.status.value}, {first.nodes} nodes): its incumbent, no stage 2 | "
            f"{stage1_s:.1f} | - | - | {start:.4f} | 0 | {int(round(staged.impact_count.value(x0)))} | - |"]
    rows.append(row("none (the incumbent, polished)", x0, 0.0, None, "skipped"))
    print(rows[-2] + "\n" + rows[-1], flush=True)
    for nodes in cuts:
        x, stats = refine(staged, x0, dataclasses.replace(config, refine_nodes=nodes))
        label = f"{nodes} nodes, warm" + (" (default)" if nodes == PlannerConfig().refine_nodes else "")
        rows.append(row(label, x, stats["refine_s"], stats["refine_nodes_explored"], stats["refine_status"]))
        print(rows[-1], flush=True)
    # the same 20-node cut without the warm start, the better of its incumbent and stage 1's kept
    x, stats = refine(staged, x0, dataclasses.replace(config, refine_warm_start=False))
    rows.append(row("20 nodes, cold (refine_warm_start=False)", x, stats["refine_s"], stats["refine_nodes_explored"],
                    stats["refine_status"]))
    print(rows[-1], flush=True)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenarios", default=",".join(scenario_names()), help="comma-separated (default: all)")
    parser.add_argument("--cuts", default=",".join(CUTS), help=f"comma-separated from {', '.join(CUTS)}")
    parser.add_argument("--gain", action="store_true", help="what the node cut buys over the warm start (see above)")
    parser.add_argument("--gain-cuts", default=",".join(map(str, GAIN_CUTS)),
                        help="--gain: comma-separated node cuts of stage 2")
    args = parser.parse_args()
    if args.gain:
        print(f"{os.cpu_count()} CPUs; load average before: {' '.join(f'{v:.1f}' for v in os.getloadavg())}\n")
        print("| scenario | stage 2 | s | nodes | ended | stage 2 objective | gain | impacts | plan |")
        print("|---|---|---:|---:|---|---:|---:|---:|---|")
        for name in [s for s in args.scenarios.split(",") if s]:
            gain_rows(name, tuple(int(c) for c in args.gain_cuts.split(",") if c))
        print(f"\nload average after: {' '.join(f'{v:.1f}' for v in os.getloadavg())}; HiGHS, seed 0, solver "
              "threads at the solver's default")
        return
    cuts = [c for c in args.cuts.split(",") if c]
    unknown = [c for c in cuts if c not in CUTS]
    if unknown:
        parser.error(f"unknown cut(s) {', '.join(unknown)}; choose from {', '.join(CUTS)}")
    scenarios = [s for s in args.scenarios.split(",") if s]
    for name in scenarios:
        load_scenario(name)  # a bad name fails here, before minutes of solving

    print("| scenario | stage 2 cut by | machine | ended | stage 2 s | stage 2 objective | impacts | plan |")
    print("|---|---|---|---|---:|---:|---:|---|")
    for name in scenarios:
        for cut in cuts:
            for loaded in (False, True):
                print(row(name, cut, loaded), flush=True)
    print(f"\nmachine: {os.cpu_count()} CPUs; HiGHS, seed 0, solver threads at the solver's default")


if __name__ == "__main__":
    main()
