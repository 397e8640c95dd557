"""Re-fly the first seeds of robustness-benchmark cells through the benchmark's own episode function and
compare every field of every episode with the published cell (timings aside), bit for bit.

    python -m benchmarks.robustness_recheck                      # the combined cells, 10 seeds, every stack
    python -m benchmarks.robustness_recheck --axis combined --seeds 10 --scenarios corridor,relay --workers 2

This is the check that a change which must not move the expert (a layout move, a refactor) moved nothing:
the episodes fly on the sweep engine as :mod:`benchmarks.robustness` flies them (one expert per worker,
scenario and stack), so a difference is the code's, not the harness's. Prints one row per cell and exits 1
if any episode differs; writes the verdicts to ``results/robustness_recheck/cells.jsonl``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from benchmarks import open_engine
from benchmarks.robustness import NEW, RESULTS, SHIPPED, STACKS, _episode, cell_store, condition_label, plan_path
from impact_env.results_store import CellStore
from impact_env.sweep import add_engine_arguments, engine_config

TIMINGS = ("wall_s", "replan_solve_s")  # measured, not computed: they differ from run to run
OUT = Path(__file__).resolve().parents[1] / "results" / "robustness_recheck"


def differences(published: dict, again: dict) -> list[str]:
    """The fields (timings aside) in which two episode records differ."""
    keys = (set(published) | set(again)) - set(TIMINGS)
    return sorted(k for k in keys if published.get(k) != again.get(k))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenarios", default=",".join(SHIPPED + NEW))
    ap.add_argument("--stacks", default=",".join(STACKS))
    ap.add_argument("--axis", default="combined")
    ap.add_argument("--level", type=float, default=0.0)
    ap.add_argument("--seeds", type=int, default=10, help="the first N seeds of each cell (default %(default)s)")
    ap.add_argument("--results", type=Path, default=RESULTS, help="the published cells (default: %(default)s)")
    ap.add_argument("--out", type=Path, default=OUT, help="where the verdicts go (default: %(default)s)")
    add_engine_arguments(ap, default_workers=min(2, os.cpu_count() or 1))
    args = ap.parse_args(argv)
    from planners.plan import Plan

    cells = cell_store(args.results)
    verdicts = CellStore(args.out / "cells.jsonl", key=lambda c: (c["scenario"], c["stack"], c["axis"], c["level"]))
    print("| scenario | condition | stack | episodes | identical | differing fields |\n|---|---|---|---:|---:|---|")
    failed = 0
    with open_engine(engine_config(args)) as pool:
        for name in args.scenarios.split(","):
            plan = Plan.load(plan_path(args.results, name)).to_dict()
            for stack in args.stacks.split(","):
                cell = cells.get((name, stack, args.axis, f"{args.level:g}"))
                if cell is None:
                    print(f"| {name} | {condition_label(args.axis, args.level)} | {stack} | - | - | not published |")
                    continue
                published = cell["episodes"][: args.seeds]
                start = time.perf_counter()
                again = list(pool.map(_episode, [(name, stack, plan, args.axis, args.level, e["seed"])
                                                 for e in published]))
                diffs = {e["seed"]: differences(e, a) for e, a in zip(published, again)}
                same = sum(not d for d in diffs.values())
                failed += len(published) - same
                fields = sorted({f for d in diffs.values() for f in d})
                print(f"| {name} | {condition_label(args.axis, args.level)} | {stack} | {len(published)} | {same} | "
                      f"{', '.join(fields) or '-'} |", flush=True)
                verdicts.put({"scenario": name, "stack": stack, "axis": args.axis, "level": args.level,
                              "episodes": len(published), "identical": same,
                              "differing": {str(s): d for s, d in diffs.items() if d},
                              "wall_s": time.perf_counter() - start})
    print(f"\n{'all episodes identical' if not failed else f'{failed} episodes differ'}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
