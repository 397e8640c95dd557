"""An offline planner against an older commit's, in one run: whole-call time, work and the plan.

For each scenario (default: the three slowest shipped ones) and each tree (this checkout, and ``--ref``'s
``impact_env/`` and ``planners/`` exported with :mod:`benchmarks.git_tree`, 0378a64 by default), one planner
call in a fresh process, the trees alternating so that both see the same load. The scenario is this
checkout's TOML file, loaded by path in both trees (the older tree may not ship it). Both run with the
planner's defaults and their own stage-1 budget (``--time-limit`` overrides the time limit of both). Per row:
the wall and CPU time of the call, stage 1's solve time and branch-and-bound nodes (this checkout reports
them), how stage 1 ended, rho, the gap, the impacts, and the plan's fingerprint (``Plan.fingerprint``: equal
means the same curves bit for bit). ``--threads 1,2`` plans with each solver thread count (this checkout only)
to show whether the plan depends on it. The load average is printed before and after: the machine is shared,
so compare rows of one run. Rows are appended to ``--out`` (JSON lines) as they finish. Usage:

    python -m benchmarks.planner_speed [--scenarios timed_visits,relay,four_robots] [--ref 0378a64]
                                       [--repeats 1] [--threads 1,2] [--time-limit S] [--out FILE]
                                       [--planner sr|ir] [--node-limit N] [--margins M1,M2]

``--planner ir`` times the impact-robust planner instead (its objective column is delta, m/s);
``--node-limit N`` sets this checkout's stage-1 node budget (0 lifts it), to measure what a budget costs.
``--margins 0.0001,0`` plans this checkout once with each satisfaction margin (``min_robustness_m``, m): the
margin changes the model's rows, and so HiGHS's path, where it does not bind.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import time
from pathlib import Path

from benchmarks.git_tree import ROOT, export_tree, run_in_tree

SLOWEST = ("timed_visits", "relay", "four_robots")


def _cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def _planner(planner: str):
    """(config class, planning function) of ``planner`` (``sr`` or ``ir``) in the tree this process runs."""
    if planner == "ir":
        try:
            from planners.offline.impact_robust import IRPlannerConfig, plan_impact_robust
        except ImportError:  # trees before the 0.3 layout
            from planners.offline.ir_planner import IRPlannerConfig, plan_impact_robust
        return IRPlannerConfig, plan_impact_robust
    try:
        from planners.offline.spatially_robust import PlannerConfig, plan_spatially_robust
    except ImportError:
        from planners.offline.sr_planner import PlannerConfig, plan_spatially_robust
    return PlannerConfig, plan_spatially_robust


def plan_call(scenario_path: str, threads: int | None, time_limit_s: float | None, planner: str = "sr",
              node_limit: int | None = None, margin: float | None = None) -> dict:
    """One planner call with the tree's defaults (run in the tree's own process): its times, work and plan.
    ``node_limit`` 0 lifts the default node budget, ``margin`` sets ``min_robustness_m`` (this checkout's
    planners; older trees have neither)."""
    from impact_env import errors

    try:
        from impact_env.transport.scenario import load_scenario
    except ImportError:  # trees before the 0.3 layout
        from impact_env.scenario import load_scenario
    import dataclasses

    config_class, plan_fn = _planner(planner)
    config = config_class()
    budget = getattr(config, "solver_options", None)
    changes: dict = {k: v for k, v in (("threads", threads), ("time_limit_s", time_limit_s)) if v is not None}
    if node_limit is not None:
        changes["node_limit"] = node_limit or None
    if budget is not None:
        config = dataclasses.replace(config, solver_options=dataclasses.replace(budget, **changes))
    elif changes:
        config = dataclasses.replace(config, **changes)
    if margin is not None:
        config = dataclasses.replace(config, min_robustness_m=margin)
    scenario = load_scenario(scenario_path)
    start, cpu = time.perf_counter(), _cpu_s()
    ended = "optimal"
    try:
        plan = plan_fn(scenario, config)
    except errors.ImpactEnvError as exc:
        plan = getattr(exc, "plan", None)
        if plan is None:
            raise
        ended = type(exc).__name__
    wall, cpu = time.perf_counter() - start, _cpu_s() - cpu
    stats = plan.stats
    if ended == "optimal" and plan.mip_gap > 1e-3:
        ended = "node_limit"
    objective = plan.robustness if planner == "sr" else float(plan.delta_mps)
    return {"wall_s": wall, "cpu_s": cpu, "stage1_s": plan.solve_time_s, "stage1_nodes": stats.get("stage1_nodes"),
            "stage2_s": stats.get("refine_s"), "ended": ended, "objective": objective, "rho": plan.robustness,
            "gap": plan.mip_gap, "impacts": len(plan.impacts), "fingerprint": plan.fingerprint()}


def _load() -> str:
    return " ".join(f"{x:.1f}" for x in os.getloadavg())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenarios", default=",".join(SLOWEST), help="comma-separated shipped names")
    parser.add_argument("--ref", default="0378a64", help="the commit to compare against ('' for none)")
    parser.add_argument("--repeats", type=int, default=1, help="calls per scenario and tree")
    parser.add_argument("--threads", default="", help="comma-separated solver thread counts for this checkout "
                                                      "(default: the solver's choice)")
    parser.add_argument("--time-limit", type=float, default=None, help="stage-1 time limit of both trees (s)")
    parser.add_argument("--out", default=None, help="JSON-lines file the rows are appended to")
    parser.add_argument("--planner", choices=("sr", "ir"), default="sr", help="spatially robust (rho) or "
                        "impact-robust (delta)")
    parser.add_argument("--node-limit", type=int, default=None, help="stage-1 node budget of this checkout (0: none; "
                        "default: the planner's)")
    parser.add_argument("--margins", default="", help="comma-separated satisfaction margins (min_robustness_m, m) "
                        "this checkout is planned with, one row each (default: the planner's)")
    args = parser.parse_args()
    if args.node_limit is not None and args.node_limit < 0:
        parser.error(f"--node-limit must be >= 0, got {args.node_limit}")
    if args.repeats < 1:
        parser.error(f"--repeats must be >= 1, got {args.repeats}")
    names = [s for s in args.scenarios.split(",") if s]
    folder = ROOT / "impact_env" / "transport" / "scenarios"
    missing = [n for n in names if not (folder / f"{n}.toml").is_file()]
    if missing:
        parser.error(f"not shipped: {', '.join(missing)}")
    try:
        margins = [float(m) for m in args.margins.split(",") if m] or [None]
    except ValueError:
        parser.error(f"--margins must be comma-separated numbers, got {args.margins!r}")
    if any(m is not None and not 0 <= m <= 1 for m in margins):
        parser.error(f"--margins must lie in [0, 1] (m), got {args.margins!r}")
    threads = [int(t) for t in args.threads.split(",") if t] or [None]
    trees = [("this checkout" + ("" if m is None else f", margin {m:g} m"), str(ROOT), threads, args.node_limit, m)
             for m in margins]
    if args.ref:
        trees.append((args.ref, export_tree(args.ref), [None], None, None))
    out = Path(args.out) if args.out else None

    print(f"{os.cpu_count()} CPUs; load average before: {_load()}\n")
    objective = "rho (m)" if args.planner == "sr" else "delta (m/s)"
    print(f"{args.planner} planner\n")
    print("| scenario | tree | threads | wall s | cpu s | stage 1 s | stage 1 nodes | stage 2 s | ended | "
          f"{objective} | gap | impacts | plan | load |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---|---:|---:|---:|---|---|")
    for name in names:
        path = str(folder / f"{name}.toml")
        for repeat in range(args.repeats):
            for label, tree, counts, node_limit, margin in trees:
                for n in counts:
                    r = run_in_tree(tree, "benchmarks.planner_speed:plan_call", path, n, args.time_limit,
                                    args.planner, node_limit, margin)
                    load = _load()
                    nodes = "-" if r["stage1_nodes"] is None else str(r["stage1_nodes"])
                    stage2 = "-" if r["stage2_s"] is None else f"{r['stage2_s']:.1f}"
                    print(f"| {name} | {label} | {n or 'default'} | {r['wall_s']:.1f} | {r['cpu_s']:.1f} | "
                          f"{r['stage1_s']:.1f} | {nodes} | {stage2} | {r['ended']} | {r['objective']:.5g} | "
                          f"{100 * r['gap']:.2f}% | {r['impacts']} | `{r['fingerprint']}` | {load} |", flush=True)
                    if out is not None:
                        with out.open("a") as f:
                            f.write(json.dumps({"scenario": name, "tree": label, "planner": args.planner,
                                                "threads": n, "node_limit": node_limit, "margin": margin,
                                                "repeat": repeat,
                                                "load": load, **r}) + "\n")
    print(f"\nload average after: {_load()}")


if __name__ == "__main__":
    main()
