"""Do the offline planner and the mission layer agree on hand-overs, and what does it change in closed loop?

    python -m benchmarks.handover_agreement [--ref 3da28cf] [--seeds 10] [--scenarios a,b]
        [--out results/handover_agreement]

Flies the same cells under this checkout and under ``--ref`` (its ``impact_env/`` and ``planners/``,
:mod:`benchmarks.git_tree`; by default main before the two layers shared one hand-over test), in the same run:

- ``check``: the mission check at 10.1 s of the regression case (``tests/data/two_objects_replan_at_10s.json``,
  the default planner and mission configs): the record's status, the re-plan's robustness, why it was refused;
- episodes of the full stack (``all``) on every scenario with a plan in ``results/robustness/plans`` (or
  ``--scenarios``) at the simulator's restitution off by 0.3 (2 seeds), the combined condition and 0.02 m/s
  post-impact noise (``--seeds`` each), with the robustness benchmark's plans and env options
  (:mod:`benchmarks.robustness`): success, robustness, and the mission's re-plan records.

Cells go to ``--out``/cells.jsonl (one per tree and condition, resumable), the table to ``--out``/table.md.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "results" / "handover_agreement"
CASE = ROOT / "tests" / "data" / "two_objects_replan_at_10s.json"
PLANS = ROOT / "results" / "robustness" / "plans"
AXES = (("e", 0.3), ("combined", 0.0), ("impact", 0.02))


def conditions(scenarios: list[str]) -> list[tuple[str, str, float]]:
    return [(s, a, lv) for s in scenarios for a, lv in AXES]


def mission_check() -> dict:
    """The regression case's mission check at 10.1 s (run in a tree: imports inside)."""
    import json

    import numpy as np

    from impact_env.transport.scenario import load_scenario
    from planners.online.bookkeeping import ImpactBook
    from planners.online.mission import MissionConfig, MissionPlanner
    from planners.plan import Plan

    case = json.loads(CASE.read_text())
    scenario = load_scenario(case["scenario"])
    plan = Plan.from_dict(case["plan"])
    planner = MissionPlanner(scenario, plan, MissionConfig(), aim_final_position=True)
    planner.trace = list(np.array(case["trace_m"])[:-1])
    book = ImpactBook(plan.impacts, tolerance_s=2.0)
    book.done = {0}
    new = planner.step(case["time_s"], np.array(case["states"]), {n: i for i, n in enumerate(case["bodies"])}, plan,
                       book, True, None)
    record = planner.records[0]
    impacts = [] if new is None else [(round(i.time_s, 2), i.robot, i.object) for i in new[0].impacts
                                      if i.time_s > case["time_s"]]
    return {"status": record.status, "new_robustness": record.new_robustness, "rejected": record.rejected,
            "impacts": impacts}


def episodes(scenario_name: str, axis: str, level: float, seeds: list[int]) -> list[dict]:
    """The full stack's episodes of one condition (run in a tree: imports inside)."""
    from benchmarks.robustness import env_options, expert_config
    from impact_env.rollout import run_episode
    from impact_env.transport.gym_env import TransportEnv
    from impact_env.transport.scenario import load_scenario
    from planners.expert import Expert
    from planners.plan import Plan

    scenario = load_scenario(scenario_name)
    plan = Plan.load(PLANS / f"{scenario_name}.json")
    out = []
    for seed in seeds:
        expert = Expert(scenario, plan=plan, config=expert_config("all"))
        res = run_episode(TransportEnv(scenario, **env_options(scenario, axis, level, seed)), expert, seed=seed)
        records = expert.report().get("mission", {}).get("records", [])
        out.append({"seed": seed, "success": bool(res.success), "robustness": float(res.robustness),
                    "statuses": [r["status"] for r in records]})
    return out


def _seeds(axis: str, seeds: int) -> list[int]:
    return list(range(2 if axis == "e" else seeds))


def run(ref: str, seeds: int, scenarios: list[str], out: Path) -> list[dict]:
    from benchmarks.git_tree import export_tree, run_in_tree
    from impact_env.results_store import CellStore

    store = CellStore(out / "cells.jsonl", key=lambda c: (c["tree"], c["cell"]))
    trees = {"this checkout": str(ROOT), ref: None}
    for name in trees:
        jobs = [("check", "benchmarks.handover_agreement:mission_check", ())]
        jobs += [(f"{s} {a} {lv:g}", "benchmarks.handover_agreement:episodes", (s, a, lv, _seeds(a, seeds)))
                 for s, a, lv in conditions(scenarios)]
        for cell, function, args in jobs:
            if (name, cell) in store:
                continue
            if trees[name] is None:
                trees[name] = export_tree(ref)
            print(f"{name}: {cell}", flush=True)
            store.put({"tree": name, "cell": cell, "result": run_in_tree(trees[name], function, *args)})
    return store.cells()


def table(cells: list[dict], ref: str, scenarios: list[str]) -> str:
    by = {(c["tree"], c["cell"]): c["result"] for c in cells}
    lines = ["| cell | tree | result |", "|---|---|---|"]
    for tree in ("this checkout", ref):
        check = by.get((tree, "check"))
        if check is not None:
            what = f"{check['status']}, re-plan {check['new_robustness']:+.4f} m"
            if check["rejected"]:
                what += " (" + "; ".join(check["rejected"]) + ")"
            lines.append(f"| mission check at 10.1 s | {tree} | {what} |")
    lines += ["", "| condition | tree | success | mean robustness (m) | min (m) | accepted re-plans | "
              "kept for a side switch | episodes that differ |", "|---|---|---:|---:|---:|---:|---:|---:|"]
    for s, a, lv in conditions(scenarios):
        cell = f"{s} {a} {lv:g}"
        mine, theirs = by.get(("this checkout", cell)), by.get((ref, cell))
        for tree, eps in (("this checkout", mine), (ref, theirs)):
            if eps is None:
                continue
            rho = [e["robustness"] for e in eps]
            accepted = sum(st.startswith("accepted") for e in eps for st in e["statuses"])
            switch = sum(st.startswith("kept: side switch") for e in eps for st in e["statuses"])
            differ = "" if mine is None or theirs is None else str(sum(
                x["robustness"] != y["robustness"] for x, y in zip(mine, theirs)))
            lines.append(f"| {cell} | {tree} | {sum(e['success'] for e in eps)}/{len(eps)} | "
                         f"{sum(rho) / len(rho):+.3f} | {min(rho):+.3f} | {accepted} | {switch} | {differ} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--ref", default="3da28cf", help="the baseline commit (default: %(default)s)")
    ap.add_argument("--seeds", type=int, default=10, help="seeds per condition, 2 on the e axis (%(default)s)")
    ap.add_argument("--scenarios", default=",".join(sorted(p.stem for p in PLANS.glob("*.json"))),
                    help="comma-separated (default: every plan in results/robustness/plans)")
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args(argv)
    from impact_env.results_store import check_output_folder, write_atomic

    scenarios = [s for s in args.scenarios.split(",") if s]
    unknown = [s for s in scenarios if not (PLANS / f"{s}.json").exists()]
    if unknown:
        ap.error(f"--scenarios: no plan in {PLANS} for {', '.join(unknown)}")
    out = check_output_folder(args.out, "--out")
    text = table(run(args.ref, args.seeds, scenarios, out), args.ref, scenarios)
    write_atomic(out / "table.md", text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
