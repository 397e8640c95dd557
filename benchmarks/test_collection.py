"""Collection time of the test suite: ``pytest --collect-only -q`` of this checkout against an older commit's.

The older commit's whole tree is exported with ``git archive`` into a temporary folder; each collection runs
in a fresh Python with the tree as working folder and on ``PYTHONPATH``, so that it imports its own
``impact_env``, ``planners``, ``baselines`` and ``tests`` (checked before timing). The two trees alternate,
round after round (the order flipped every round), after one untimed collection of each (it writes the
bytecode and pytest's rewritten test modules, as any second run finds them; ``PYTHONDONTWRITEBYTECODE`` is
not passed on). Prints the median and minimum
wall-clock seconds per tree and the current tree's ratio to the older one, and keeps one cell per collection
in ``results/test_collection/cells.jsonl`` (and the table in ``table.md``). Usage::

    python -m benchmarks.test_collection [--ref 0378a64] [--runs 7]

0378a64 is the last commit before the tests mirrored the source tree (issue 20), when collecting took ~5 s
on an idle 2-core machine.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import statistics
import subprocess
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

from benchmarks.git_tree import ROOT, export_tree

RESULTS = ROOT / "results" / "test_collection"
COLLECTED = re.compile(r"(\d+)(?:/(\d+))? tests? collected")
ORIGINS = "import impact_env, planners, baselines, tests; print(impact_env.__file__, planners.__file__, " \
          "baselines.__file__, tests.__file__)"


def environment(tree: Path) -> dict[str, str]:
    """The environment of a collection in ``tree``: the tree first on the path, nothing else of ours, and
    bytecode written (without, under ``PYTHONDONTWRITEBYTECODE``, every run compiles both trees' sources)."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    return {**env, "PYTHONPATH": str(tree)}


def check_origins(tree: Path) -> None:
    """Exit if Python started in ``tree`` would import any of the four packages from elsewhere."""
    out = subprocess.run([sys.executable, "-c", ORIGINS], cwd=tree, env=environment(tree), check=True,
                         capture_output=True, text=True).stdout.split()
    stray = [path for path in out if not Path(path).resolve().is_relative_to(tree.resolve())]
    if stray:
        raise SystemExit(f"collecting in {tree} would import {stray}, not the tree's own packages")


def collect(tree: Path) -> tuple[float, int]:
    """Wall-clock seconds of one ``python -m pytest --collect-only -q`` in ``tree``, and the number of tests it
    selected (the default run: ``-m "not slow"``)."""
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "pytest", "--collect-only", "-q"], cwd=tree, env=environment(tree),
                          capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if done.returncode != 0:
        sys.stdout.write(done.stdout[-3000:])
        raise SystemExit(f"pytest --collect-only in {tree} exited with status {done.returncode}")
    return seconds, tests_collected(done.stdout)


def tests_collected(output: str) -> int:
    """The selected tests in pytest's last line: ``1169/1321 tests collected (152 deselected)`` -> 1169."""
    found = COLLECTED.findall(output)
    if not found:
        raise ValueError(f"no 'N tests collected' line in pytest's output: {output[-300:]!r}")
    return int(found[-1][0])


def table(times: dict[str, list[float]], tests: dict[str, int], ref: str) -> str:
    """Markdown: per tree its runs, median and minimum seconds, the ratio of medians to ``ref``, and tests."""
    base = statistics.median(times[ref])
    rows = ["| tree | runs | median (s) | min (s) | median / " + ref + " | tests collected |",
            "|---|---:|---:|---:|---:|---:|"]
    for name, values in times.items():
        median = statistics.median(values)
        rows.append(f"| {name} | {len(values)} | {median:.2f} | {min(values):.2f} | {median / base:.2f} | "
                    f"{tests[name]} |")
    return "\n".join(rows)


def key_of(cell: dict) -> tuple[str, str, int]:
    """A cell is one collection: (session start, tree, round)."""
    return cell["session"], cell["tree"], int(cell["round"])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--ref", default="0378a64", help="the older commit (default: before issue 20's tests)")
    parser.add_argument("--runs", type=int, default=7, help="timed collections per tree")
    parser.add_argument("--out", type=Path, default=RESULTS, help="folder of cells.jsonl and table.md")
    args = parser.parse_args(argv)

    from impact_env.results_store import CellStore, write_atomic

    ref_label = f"{args.ref} (git archive)"
    head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                          text=True, check=True).stdout.strip()
    dirty = subprocess.run(["git", "-C", str(ROOT), "status", "--porcelain", "--untracked-files=no"],
                           capture_output=True, text=True, check=True).stdout.strip()
    current_label = f"this checkout ({head}{', modified' if dirty else ''})"
    ref_tree = Path(export_tree(args.ref, prefix="impact_env_collect_", paths=None))
    trees = {ref_label: ref_tree, current_label: ROOT}
    session = datetime.now(timezone.utc).isoformat(timespec="seconds")
    store = CellStore(args.out / "cells.jsonl", key=key_of)
    times: dict[str, list[float]] = {name: [] for name in trees}
    tests: dict[str, int] = {}
    try:
        for tree in trees.values():
            check_origins(tree)
            collect(tree)  # untimed: bytecode and rewritten test modules, as a second run finds them
        print(f"{args.runs} rounds, {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f} at the start")
        for k in range(args.runs):
            order = list(trees) if k % 2 == 0 else list(reversed(trees))
            for name in order:
                load = os.getloadavg()[0]
                seconds, count = collect(trees[name])
                times[name].append(seconds)
                tests[name] = count
                store.put({"session": session, "tree": name, "round": k, "seconds": round(seconds, 4),
                           "tests_collected": count, "ref": args.ref, "head": head, "modified": bool(dirty),
                           "load_1min": round(load, 2), "cpus": os.cpu_count(),
                           "python": sys.version.split()[0]})
                print(f"  round {k + 1}: {name}: {seconds:.2f} s", flush=True)
    finally:
        shutil.rmtree(ref_tree, ignore_errors=True)
    text = table(times, tests, ref_label)
    print()
    print(text)
    write_atomic(args.out / "table.md", f"`python -m benchmarks.test_collection --ref {args.ref} --runs {args.runs}`, "
                 f"{session}, load average {os.getloadavg()[0]:.1f} at the end:\n\n{text}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
