"""Planner stage 2 (fewest impacts, least L1 acceleration, rho kept): cut by nodes or by time, idle or loaded.

Stage 2 rarely proves its optimum quickly, so it is cut short. This compares, in one run, the default cut
(``refine_nodes=20``, deterministic work) with the cut used before it (a 5 s time limit) and with a long
reference (60 s), each once on an idle machine and once with every core busy (one spinning process per
CPU, started by this script). For each row: how stage 2 ended, its time, its objective (impacts plus the
scaled acceleration term: lower is better) and the plan's fingerprint (``Plan.fingerprint``: equal means
the same curves bit for bit). A cut that is deterministic gives the same fingerprint idle and loaded.
Prints a markdown table. Usage:

    python -m benchmarks.planner_stage2 [--scenarios a,b,c] [--cuts nodes,time5,time60]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenarios", default=",".join(scenario_names()), help="comma-separated (default: all)")
    parser.add_argument("--cuts", default=",".join(CUTS), help=f"comma-separated from {', '.join(CUTS)}")
    args = parser.parse_args()
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
