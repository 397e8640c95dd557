"""Compare two ``episodes.csv`` files of ``impact-env bench`` episode by episode, every column but the timing.

    python -m benchmarks.compare_episodes A/episodes.csv B/episodes.csv

The check that a change which must not move any controller moved nothing: fly the same bench before and after
(e.g. the tree of another commit exported with ``git archive`` and run with ``PYTHONPATH`` set to it, see
``docs/layout.md``), then compare. Exits 1 if an episode of B differs from A's or is missing in A.
"""

from __future__ import annotations

import argparse
import csv
import sys

TIMINGS = ("controller_ms",)


def compare(a_path: str, b_path: str) -> list[str]:
    """One line per episode of ``b_path`` that is missing in ``a_path`` or differs from it (timings aside)."""
    with open(a_path, newline="") as f:
        a = {(r["scenario"], r["controller"], r["seed"]): r for r in csv.DictReader(f)}
    with open(b_path, newline="") as f:
        b = list(csv.DictReader(f))
    out = []
    for row in b:
        key = (row["scenario"], row["controller"], row["seed"])
        if key not in a:
            out.append(f"{'/'.join(key)}: not in {a_path}")
            continue
        fields = [k for k in row if k not in TIMINGS and row[k] != a[key].get(k)]
        if fields:
            out.append(f"{'/'.join(key)}: " + ", ".join(f"{k} {a[key].get(k)} -> {row[k]}" for k in fields))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("a")
    ap.add_argument("b")
    args = ap.parse_args(argv)
    with open(args.b, newline="") as f:
        n = sum(1 for _ in csv.DictReader(f))
    lines = compare(args.a, args.b)
    print("\n".join(lines) if lines else f"all {n} episodes identical")
    return 1 if lines else 0


if __name__ == "__main__":
    sys.exit(main())
