"""Opt-in parts of the full expert against the expert without them, on the robustness benchmark's episodes.

Each variant is ``ExpertConfig()`` (the robustness benchmark's ``all``) with options switched on:

- ``baseline``: none (its episodes are those of the benchmark's cells, bit for bit);
- ``later_approaches``: re-plans also test and repair each later contact of a robot whose way from its impact
  on another object must get round the object (``MissionConfig.later_approaches``);
- ``way_round``: a replanned approach that must get round its object does so (``ExpertConfig.way_round``);
- ``both``: the two.

Every variant flies the same plan (``results/robustness/plans/``), env options and seeds (``--first-seed`` on) as
the robustness benchmark (:mod:`benchmarks.robustness`), post-impact noise at ``--noise``. Cells go to
``--out``/cells.jsonl as each finishes (a rerun resumes) and the table, with the seeds each variant lost and
gained against the baseline, to ``--out``/table.md. From the repository root:

    python -m benchmarks.expert_variants [--scenarios one_robot_two_objects] [--variants baseline,later_approaches]
        [--noise 0.02] [--first-seed 0] [--seeds 50] [--workers 2] [--out results/expert_variants]
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from collections.abc import Callable
from pathlib import Path

from benchmarks import open_engine
from benchmarks.robustness import RESULTS as ROBUSTNESS
from benchmarks.robustness import _episode, expert_config, plan_for
from impact_env.results_store import CellStore, write_atomic
from impact_env.sweep import EngineConfig

RESULTS = Path(__file__).resolve().parents[1] / "results" / "expert_variants"
BASELINE = "baseline"


def _later(config):
    return dataclasses.replace(config, mission=dataclasses.replace(config.mission, later_approaches=True))


VARIANTS: dict[str, Callable] = {
    BASELINE: lambda config: config,
    "later_approaches": _later,
    "way_round": lambda config: dataclasses.replace(config, way_round=True),
    "both": lambda config: dataclasses.replace(_later(config), way_round=True),
}


def config(variant: str):
    """``ExpertConfig()`` with ``variant``'s options on."""
    return VARIANTS[variant](expert_config("all"))


def fly(job: tuple[str, str, dict, float, int]) -> dict:
    """One episode: (scenario, variant, plan as a dict, noise m/s, seed) -> the robustness benchmark's episode
    (:func:`benchmarks.robustness._episode`) flown with the variant's config."""
    name, variant, plan, noise, seed = job
    return _episode((name, f"all, {variant}", plan, "impact", noise, seed, config(variant)))


def cell_key(cell: dict) -> tuple[str, str, float, int]:
    return (str(cell["scenario"]), str(cell["variant"]), float(cell["noise_mps"]), int(cell["first_seed"]))


def fly_missing(store: CellStore, pool, key: tuple, fields: dict, fly: Callable, jobs: list) -> dict:
    """The cell ``key`` of ``store``, flown (``fly`` over ``jobs`` on ``pool``) and stored first when it is missing
    or has fewer episodes than ``jobs``; ``fields`` name it in the file, before its episodes and wall clock."""
    cell = store.get(key)
    if cell is None or len(cell["episodes"]) < len(jobs):
        start = time.perf_counter()
        episodes = list(pool.map(fly, jobs))
        cell = {**fields, "episodes": episodes, "wall_s": round(time.perf_counter() - start, 1)}
        store.put(cell)
    return cell


def against_baseline(cells: list[dict], column: Callable[[dict], object], baseline: object,
                     label: Callable[[object], str], what: str) -> str:
    """Success per scenario and column of ``cells`` (one table per noise level), with the seeds each column lost
    (-) and gained (+) against the ``baseline`` column on the same episodes, and the totals. ``column(cell)``:
    the cell's column key; ``label(key)``: its heading; ``what``: the baseline's name in the caption."""
    lines = []
    for noise in sorted({c["noise_mps"] for c in cells}):
        here = [c for c in cells if c["noise_mps"] == noise]
        columns = sorted({column(c) for c in here}, key=lambda k: (k != baseline, str(k) if isinstance(k, str)
                                                                   else k))
        names = list(dict.fromkeys(c["scenario"] for c in here))
        lines += [f"Post-impact noise {noise:g} m/s per axis, the full expert; success / episodes, and against "
                  f"{what} the seeds lost (-) and gained (+)", "",
                  "| scenario | " + " | ".join(label(k) for k in columns) + " |",
                  "|---|" + "---|" * len(columns)]
        totals = {k: [0, 0] for k in columns}
        for name in names:
            ok_of = {}
            for k in columns:
                ok: dict = {}
                for c in here:
                    if c["scenario"] == name and column(c) == k:
                        ok.update({e["seed"]: e["success"] for e in c["episodes"]})
                ok_of[k] = ok
            base = ok_of.get(baseline) or {}
            row = []
            for k in columns:
                ok = ok_of[k]
                if not ok:
                    row.append("-")
                    continue
                text = f"{sum(ok.values())} / {len(ok)}"
                if base and k != baseline:
                    lost = [s for s in sorted(ok) if s in base and base[s] and not ok[s]]
                    gained = [s for s in sorted(ok) if s in base and ok[s] and not base[s]]
                    for sign, seeds in (("-", lost), ("+", gained)):
                        text += f" {sign}{','.join(map(str, seeds))}" if seeds else ""
                row.append(text)
                totals[k][0] += sum(ok.values())
                totals[k][1] += len(ok)
            lines.append(f"| {name} | " + " | ".join(row) + " |")
        lines += ["| **all** | " + " | ".join(f"**{s} / {n}**" for s, n in totals.values()) + " |", ""]
    return "\n".join(lines)


def table(cells: list[dict]) -> str:
    return against_baseline(cells, lambda c: c["variant"], BASELINE, str, "the baseline")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], allow_abbrev=False)
    parser.add_argument("--scenarios", default="one_robot_two_objects")
    parser.add_argument("--variants", default=",".join(VARIANTS), help=f"comma-separated: {', '.join(VARIANTS)}")
    parser.add_argument("--noise", default="0.02", help="post-impact noise levels, m/s (comma-separated)")
    parser.add_argument("--first-seed", type=int, default=0)
    parser.add_argument("--seeds", type=int, default=50)
    parser.add_argument("--workers", type=int, default=None, help="local worker processes (default: the CPUs)")
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    variants = [v for v in args.variants.split(",") if v.strip()]
    unknown = [v for v in variants if v not in VARIANTS]
    if unknown:
        parser.error(f"unknown variants {unknown}: choose from {', '.join(VARIANTS)}")
    try:
        levels = [float(x) for x in args.noise.split(",") if x.strip()]
    except ValueError:
        parser.error("--noise takes comma-separated numbers")
    if any(not x >= 0 for x in levels):
        parser.error(f"--noise must be >= 0, got {args.noise!r}")
    if args.seeds < 1 or args.first_seed < 0:
        parser.error(f"--seeds must be >= 1 and --first-seed >= 0, got {args.seeds} and {args.first_seed}")
    args.out.mkdir(parents=True, exist_ok=True)
    store = CellStore(args.out / "cells.jsonl", cell_key)
    names = [s for s in args.scenarios.split(",") if s]
    seeds = list(range(args.first_seed, args.first_seed + args.seeds))
    todo = [(n, v, x) for x in levels for n in names for v in variants]
    with open_engine(EngineConfig(workers=args.workers)) as pool:
        for k, (name, variant, noise) in enumerate(todo, 1):
            plan = plan_for(name, ROBUSTNESS)
            fields = {"scenario": name, "variant": variant, "noise_mps": noise, "first_seed": args.first_seed}
            cell = fly_missing(store, pool, (name, variant, noise, args.first_seed), fields, fly,
                               [(name, variant, plan, noise, s) for s in seeds])
            print(f"[{k}/{len(todo)}] {name} {variant} at {noise:g} m/s, seeds {seeds[0]}-{seeds[-1]}: "
                  f"{sum(e['success'] for e in cell['episodes'])} / {len(cell['episodes'])} ({cell['wall_s']:.0f} s)",
                  flush=True)
    text = table(store.cells())
    write_atomic(args.out / "table.md", text)
    print("\n" + text)


if __name__ == "__main__":
    main()
