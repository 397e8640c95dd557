"""The expert on the planner-kept generated tasks: this tree against another commit, on the same episodes.

The task generator's benchmark (:mod:`benchmarks.task_generator`) flies each kept task once, with the tree of
the day it was planned. This flies every kept task of a family folder again, with ``--seeds`` env seeds per
task under one condition (nominal, or one axis of :mod:`benchmarks.robustness`: ``--axis impact --level
0.02``), for this checkout and, with ``--ref REF``, for that commit's ``impact_env/`` and ``planners/``
(exported with ``git archive``) in the same run, so that an expert change is judged on tasks nobody tuned it
for. Both trees fly in child processes (:func:`benchmarks.git_tree.run_in_tree`), ``--workers`` at a time,
in chunks of ``--chunk`` episodes; every episode is a line of ``--out``/cells.jsonl keyed by the tree's commit
(this checkout's HEAD, ``+dirty`` when impact_env/ or planners/ have uncommitted changes), so a stopped run
resumes. The table: per family and tree, success with a Wilson 95 % interval, mean robustness, the share of
episodes with more robot-object impacts than the plan has, and the median ms per step; then, against the
ref, the episodes only one tree delivers and McNemar's exact two-sided p. From the repository root:

    python -m benchmarks.generated_expert --families throw_and_catch --ref 9c46510 [--axis impact --level 0.02]
    python -m benchmarks.generated_expert --table-only
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

AXES = ("nominal", "impact", "thrust", "offset")
OUT = Path("results/generated_expert")
TASKS = Path("results/task_generator")


def fly_batch(jobs: list[dict]) -> list[dict]:
    """Fly each job (a kept task's TOML text and plan, the stack, the condition and the env seed) with the
    ``impact_env`` and ``planners`` this process imports; one record per job. Imports nothing at module level:
    it runs under an older tree too."""
    from benchmarks.task_generator import fly
    from impact_env.transport.scenario_toml import scenario_from_toml
    from planners.expert.stacks import stack_config
    from planners.plan import Plan

    out = []
    for job in jobs:
        scenario = scenario_from_toml(job["toml"], source=job["name"])
        plan = Plan.from_dict(job["plan"])
        options = {"nominal": {}, "impact": {"impact_velocity_noise_mps": job["level"]},
                   "thrust": {"thrust_noise": job["level"]},
                   "offset": {"initial_position_noise_m": job["level"]}}[job["axis"]]
        flight = fly(scenario, plan, job["seed"], config=stack_config(job["stack"]), env_options=options)
        out.append({"success": flight["success"], "robustness": flight["robustness_m"],
                    "impacts": flight["impacts"], "planned_impacts": len(plan.impacts), "steps": flight["steps"],
                    "ms_per_step": flight["ms_per_step"], "wall_s": flight["wall_s"]})
    return out


def commit_of(ref: str | None) -> str:
    """12 hex digits of ``ref`` (None: this checkout's HEAD, with ``+dirty`` when impact_env/ or planners/ have
    uncommitted changes, whose flights no commit names)."""
    root = Path(__file__).resolve().parents[1]
    head = subprocess.run(["git", "-C", str(root), "rev-parse", "--short=12", ref or "HEAD"], check=True,
                          capture_output=True, text=True).stdout.strip()
    if ref is None and subprocess.run(["git", "-C", str(root), "status", "--porcelain", "impact_env", "planners"],
                                      check=True, capture_output=True, text=True).stdout.strip():
        head += "+dirty"
    return head


def key_of(cell: dict) -> tuple:
    return cell["tree"], cell["name"], cell["stack"], cell["axis"], f"{cell['level']:g}", cell["seed"]


def kept_jobs(folder: Path, family: str, stack: str, axis: str, level: float, seeds: int) -> list[dict]:
    """A job per kept task of ``folder``/``family`` (its verdict kept, its TOML and plan there) and env seed."""
    verdicts = folder / family / "verdicts.jsonl"
    if not verdicts.is_file():
        raise SystemExit(f"{verdicts.parent} has no verdicts.jsonl: plan tasks into it first "
                         f"(python -m benchmarks.task_generator --families {family})")
    jobs = []
    for line in verdicts.read_text(encoding="utf-8").splitlines():
        verdict = json.loads(line)
        toml, plan = folder / family / f"{verdict['name']}.toml", folder / family / f"{verdict['name']}.plan.json"
        if not (verdict["kept"] and toml.is_file() and plan.is_file()):
            continue
        for seed in range(seeds):
            jobs.append({"name": verdict["name"], "family": family, "task_seed": verdict["seed"], "stack": stack,
                         "axis": axis, "level": level, "seed": seed, "toml": toml.read_text(encoding="utf-8"),
                         "plan": json.loads(plan.read_text(encoding="utf-8"))})
    return sorted(jobs, key=lambda j: (j["task_seed"], j["seed"]))


def fly_trees(jobs: list[dict], trees: dict[str, str], store, workers: int, chunk: int) -> None:
    """Fly every job not yet in ``store`` under each tree (commit -> folder), ``workers`` child processes at a
    time, ``chunk`` episodes per child; each chunk's cells are stored as it ends."""
    from benchmarks.git_tree import run_in_tree

    todo = []
    for commit, tree in trees.items():
        left = [j for j in jobs if key_of({**j, "tree": commit}) not in store]
        todo += [(commit, tree, left[i:i + chunk]) for i in range(0, len(left), chunk)]
    total = sum(len(c) for *_, c in todo)
    print(f"{total} episodes to fly in {len(todo)} chunks", flush=True)
    done = 0

    def one(item):
        commit, tree, batch = item
        records = run_in_tree(tree, "benchmarks.generated_expert:fly_batch", batch)
        return [{**{k: v for k, v in j.items() if k not in ("toml", "plan")}, "tree": commit, **r}
                for j, r in zip(batch, records, strict=True)]

    with ThreadPoolExecutor(max_workers=workers) as pool:
        for cells in pool.map(one, todo):
            store.put_many(cells)
            done += len(cells)
            won = sum(c["success"] for c in cells)
            print(f"  {cells[0]['tree']}: {done} / {total} episodes ({won} of the last {len(cells)} delivered)",
                  flush=True)


def table(cells: list[dict], ref: str | None = None) -> str:
    """Per family, condition and tree: success (Wilson 95 %), robustness, extra impacts, ms per step; against
    ``ref`` (a commit in the cells), the paired episodes only one tree delivers and McNemar's p."""
    import numpy as np

    from benchmarks.residual import mcnemar
    from benchmarks.task_generator import wilson

    lines = ["| family | condition | tree | episodes (tasks) | success % (95 % CI) | robustness m (mean) | "
             "with more impacts than planned | ms/step (median) | only this / only ref | McNemar p |",
             "|---|---|---|---:|---:|---:|---:|---:|---|---:|"]
    groups: dict[tuple, dict[str, list[dict]]] = {}
    for c in cells:
        groups.setdefault((c["family"], c["axis"], c["level"], c["stack"]), {}).setdefault(c["tree"], []).append(c)
    for (family, axis, level, stack), trees in sorted(groups.items()):
        condition = "nominal" if axis == "nominal" else f"{axis} {level:g}"
        base = {(c["name"], c["seed"]): c["success"] for c in trees.get(ref, [])} if ref else {}
        for tree, rows in sorted(trees.items(), key=lambda kv: (kv[0] == ref, kv[0])):
            k, n = sum(r["success"] for r in rows), len(rows)
            lo, hi = wilson(k, n)
            extra = sum(r["impacts"] > r["planned_impacts"] for r in rows)
            paired = "-"
            p = "-"
            if ref and tree != ref:
                both = [(base[(r["name"], r["seed"])], r["success"]) for r in rows if (r["name"], r["seed"]) in base]
                if both:
                    test = mcnemar(np.array([b for b, _ in both]), np.array([s for _, s in both]))
                    paired = f"{test['only_residual']} / {test['only_expert']} of {len(both)}"
                    p = f"{test['p_two_sided']:.3f}"
            tasks = len({r["name"] for r in rows})
            lines.append(f"| {family} | {condition} | {tree}{' (ref)' if tree == ref else ''} ({stack}) | "
                         f"{n} ({tasks}) | {100 * k / n:.0f} ({100 * lo:.0f}-{100 * hi:.0f}) | "
                         f"{statistics.fmean(r['robustness'] for r in rows):+.3f} | {extra} | "
                         f"{statistics.median(r['ms_per_step'] for r in rows):.1f} | {paired} | {p} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    from benchmarks.git_tree import ROOT, export_tree
    from impact_env.results_store import CellStore, write_atomic

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--families", default="throw_and_catch", help="comma-separated task families")
    parser.add_argument("--tasks", type=Path, default=TASKS,
                        help="the task generator's folder (<family>/verdicts.jsonl, .toml, .plan.json)")
    parser.add_argument("--stack", default="all", help="the expert's stack (paper, +id, +mission, all)")
    parser.add_argument("--axis", choices=AXES, default="nominal")
    parser.add_argument("--level", type=float, default=0.0, help="the axis's level (m/s, fraction or m)")
    parser.add_argument("--seeds", type=int, default=1, help="env seeds per task")
    parser.add_argument("--ref", help="a commit to fly the same episodes with, in the same run")
    parser.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    parser.add_argument("--chunk", type=int, default=10, help="episodes per child process")
    parser.add_argument("--out", type=Path, default=OUT, help="cells.jsonl and table.md (default: %(default)s)")
    parser.add_argument("--table-only", action="store_true", help="print the table of the cells there and stop")
    args = parser.parse_args(argv)
    if args.axis == "nominal" and args.level != 0:
        parser.error("--level needs an --axis other than nominal")
    if args.axis != "nominal" and args.level <= 0:
        parser.error(f"--axis {args.axis} needs a --level > 0")
    if args.seeds < 1 or args.workers < 1 or args.chunk < 1:
        parser.error("--seeds, --workers and --chunk must be at least 1")
    store = CellStore(args.out / "cells.jsonl", key=key_of)
    ref = commit_of(args.ref) if args.ref else None
    if not args.table_only:
        trees = {commit_of(None): str(ROOT)}
        if ref and ref not in trees:  # (the same commit as this checkout: its flights are this tree's)
            trees[ref] = export_tree(args.ref)
        jobs = [j for family in args.families.split(",")
                for j in kept_jobs(args.tasks, family, args.stack, args.axis, args.level, args.seeds)]
        fly_trees(jobs, trees, store, args.workers, args.chunk)
    cells = store.cells()
    if not cells:
        print(f"no cells in {args.out}")
        return 0
    text = table(cells, ref)
    write_atomic(args.out / "table.md", text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
