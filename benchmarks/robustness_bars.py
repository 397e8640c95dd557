"""The robustness grid against the two bars the expert is held to under post-impact noise.

Reads the cells of :mod:`benchmarks.robustness` (``--out``/cells.jsonl; it flies nothing) and prints three
tables:

1. **The noise bar**: the full stack (``all``) at ``--rate`` (95 %) or more in every post-impact noise cell up
   to ``--up-to`` (0.02 m/s), on every scenario.
2. **Against the paper's stack**: in every cell both stacks flew (noise, restitution, offset and thrust axes),
   on the seeds both flew, the full stack may succeed at most ``--slack`` (1) episode less often than the
   paper's stack. The seeds only the paper's stack won are listed, to re-fly them with
   ``python -m benchmarks.robustness_episode``.
3. **The grid**: which of the cells the bars need are missing, short of ``--seeds`` episodes, or flown with
   an earlier config of their stack (``--stale`` of :mod:`benchmarks.robustness` flies those again).

A cell that is stale or short still counts in the first two tables, marked, so a partial grid says where it
stands. ``--check`` exits 1 unless every bar holds on a complete, current grid. From the repository root:

    python -m benchmarks.robustness_bars [--out results/robustness] [--check]
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

from benchmarks.robustness import (
    AXES,
    NEW,
    RESULTS,
    SHIPPED,
    cell_key,
    cell_seeds,
    config_fingerprint,
    counts_as,
    load_cells,
)

BAR_AXES = ("e", "offset", "thrust", "impact")


@dataclass(frozen=True)
class Bars:
    """What the bars ask: ``rate`` of success for ``all`` in every impact cell up to ``up_to`` m/s; ``all`` at
    most ``slack`` successes below ``paper`` on shared seeds; ``seeds`` episodes per cell."""

    rate: float = 0.95
    up_to: float = 0.02
    slack: int = 1
    seeds: int = 50


def successes(cell: dict) -> dict[int, bool]:
    """Seed -> success of a cell's episodes."""
    return {e["seed"]: bool(e["success"]) for e in cell["episodes"]}


def current(cell: dict, fingerprints: dict[str, str]) -> bool:
    """Whether the cell was flown with its stack's config of today (through ``SAME_FLIGHTS``)."""
    return counts_as(cell) == fingerprints[cell["stack"]]


def short(cell: dict, bars: Bars) -> bool:
    """Whether the cell has fewer episodes than its axis needs (``bars.seeds``; the e axis two, one per sign)."""
    return len(cell["episodes"]) < cell_seeds(cell["axis"], bars.seeds)


def mark(cells: tuple[dict, ...], fingerprints: dict[str, str], bars: Bars) -> str:
    """`` *`` when one of ``cells`` is stale, `` (short)`` when one has fewer episodes than it needs."""
    return (" *" if not all(current(c, fingerprints) for c in cells) else "") + \
        (" (short)" if any(short(c, bars) for c in cells) else "")


def noise_rows(cells: list[dict], scenarios, fingerprints, bars: Bars) -> list[tuple[str, float, str, bool]]:
    """(scenario, level, ``k / n`` with its marks, holds) for every ``all`` impact cell up to ``bars.up_to``."""
    rows = []
    for cell in cells:
        if (cell["stack"] == "all" and cell["axis"] == "impact" and cell["level"] <= bars.up_to + 1e-12
                and cell["scenario"] in scenarios):
            won = sum(successes(cell).values())
            n = len(cell["episodes"])
            rows.append((cell["scenario"], cell["level"], f"{won} / {n}{mark((cell,), fingerprints, bars)}",
                         won >= bars.rate * n))
    return sorted(rows, key=lambda r: (list(scenarios).index(r[0]), r[1]))


@dataclass
class Gap:
    """One condition both stacks flew: successes on the shared seeds and the seeds only one stack won."""

    scenario: str
    axis: str
    level: float
    shared: int
    paper: int
    all: int
    paper_only: list[int]
    all_only: list[int]
    marks: str

    def holds(self, slack: int) -> bool:
        return self.paper - self.all <= slack


def gaps(cells: list[dict], scenarios, fingerprints, bars: Bars) -> list[Gap]:
    """A :class:`Gap` per (scenario, axis, level) of ``BAR_AXES`` that both ``paper`` and ``all`` flew."""
    by_key = {cell_key(c["scenario"], c["stack"], c["axis"], c["level"]): c for c in cells}
    found = []
    for (scenario, stack, axis, level), cell in by_key.items():
        other = by_key.get((scenario, "paper", axis, level))
        if stack != "all" or axis not in BAR_AXES or scenario not in scenarios or other is None:
            continue
        mine, theirs = successes(cell), successes(other)
        seeds = sorted(mine.keys() & theirs.keys())
        found.append(Gap(scenario, axis, cell["level"], len(seeds), sum(theirs[s] for s in seeds),
                         sum(mine[s] for s in seeds), [s for s in seeds if theirs[s] and not mine[s]],
                         [s for s in seeds if mine[s] and not theirs[s]],
                         mark((cell, other), fingerprints, bars).strip()))
    return sorted(found, key=lambda g: (list(scenarios).index(g.scenario), BAR_AXES.index(g.axis), g.level))


def missing(cells: list[dict], scenarios, fingerprints, bars: Bars) -> list[tuple[str, str, str, float, str]]:
    """(scenario, stack, axis, level, what) for every cell the bars need that is missing, short or stale."""
    by_key = {cell_key(c["scenario"], c["stack"], c["axis"], c["level"]): c for c in cells}
    wanted = []
    for scenario in scenarios:
        for stack in ("paper", "all"):
            for axis in BAR_AXES:
                for level in AXES[axis]:
                    cell = by_key.get(cell_key(scenario, stack, axis, level))
                    if cell is None:
                        wanted.append((scenario, stack, axis, level, "missing"))
                    elif not current(cell, fingerprints) or short(cell, bars):
                        what = ["stale"] * (not current(cell, fingerprints)) + \
                            [f"{len(cell['episodes'])} episodes"] * short(cell, bars)
                        wanted.append((scenario, stack, axis, level, ", ".join(what)))
    return wanted


def report(cells: list[dict], scenarios, bars: Bars) -> tuple[str, bool]:
    """The three tables as markdown, and whether every bar holds on a complete, current grid."""
    fingerprints = {stack: config_fingerprint(stack) for stack in ("paper", "all")}
    noise = noise_rows(cells, scenarios, fingerprints, bars)
    gap = gaps(cells, scenarios, fingerprints, bars)
    todo = missing(cells, scenarios, fingerprints, bars)
    lines = [f"## `all` under post-impact noise up to {bars.up_to:g} m/s (bar: {100 * bars.rate:g} %)", "",
             "| scenario | noise m/s | successes | holds |", "|---|---:|---:|---|"]
    lines += [f"| {s} | {lv:g} | {k} | {'yes' if ok else '**no**'} |" for s, lv, k, ok in noise]
    lines += ["", f"## `all` against `paper` on the same seeds (bar: at most {bars.slack} success below)", "",
              "| scenario | axis | level | shared seeds | paper | all | seeds only paper won | seeds only all won "
              "| holds |", "|---|---|---:|---:|---:|---:|---|---|---|"]
    lines += [f"| {g.scenario} | {g.axis} | {g.level:g} | {g.shared}{(' ' + g.marks) if g.marks else ''} | "
              f"{g.paper} | {g.all} | {', '.join(map(str, g.paper_only)) or '-'} | "
              f"{', '.join(map(str, g.all_only)) or '-'} | {'yes' if g.holds(bars.slack) else '**no**'} |"
              for g in gap]
    lines += ["", f"## Cells still to fly ({len(todo)})", ""]
    lines += [f"- {s} {st} {ax} {lv:g}: {what}" for s, st, ax, lv, what in todo] or ["none"]
    noise_ok = all(ok for *_, ok in noise)
    gap_ok = all(g.holds(bars.slack) for g in gap)
    lines += ["", "\\* flown with an earlier config of the stack; (short): fewer than "
              f"{bars.seeds} episodes (the e axis: 2, one per sign)", "",
              f"noise bar: {'holds' if noise_ok else 'fails'} in the cells flown; paper bar: "
              f"{'holds' if gap_ok else 'fails'} in the cells flown; grid: "
              f"{'complete and current' if not todo else f'{len(todo)} cells to fly'}"]
    return "\n".join(lines), noise_ok and gap_ok and not todo


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=RESULTS, help="the benchmark's folder (default: %(default)s)")
    parser.add_argument("--scenarios", default=",".join(SHIPPED + NEW))
    parser.add_argument("--rate", type=float, default=Bars.rate)
    parser.add_argument("--up-to", type=float, default=Bars.up_to, help="the noise bar's largest level, m/s")
    parser.add_argument("--slack", type=int, default=Bars.slack)
    parser.add_argument("--seeds", type=int, default=Bars.seeds, help="episodes a complete cell has")
    parser.add_argument("--check", action="store_true", help="exit 1 unless every bar holds on a complete grid")
    args = parser.parse_args(argv)
    if not (args.out / "cells.jsonl").exists():
        parser.error(f"{args.out} has no cells.jsonl: fly the grid with python -m benchmarks.robustness first")
    text, ok = report(load_cells(args.out), args.scenarios.split(","),
                      Bars(args.rate, args.up_to, args.slack, args.seeds))
    print(text)
    return 1 if args.check and not ok else 0


if __name__ == "__main__":
    sys.exit(main())
