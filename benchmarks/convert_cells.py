"""Convert a benchmark folder of per-cell JSON files (the format before ``cells.jsonl``) into the new layout.

The robustness and impact-robust benchmarks kept every cell in a file of its own
(``<scenario>__<stack>__<axis>_<level>.json``, ``<scenario>__<plan>__<stack>__<axis>_<level>.json``) beside
their cached plans (``<scenario>__plan.json``, ``<scenario>__sr_plan.json``, ``<scenario>__ir_plan.json``).
This writes ``cells.jsonl`` (one cell per line: the old file's text itself, which is ``json.dumps`` of the
cell, so every number and field stays as measured), ``table.md`` and ``plans/`` (the plan files copied byte
for byte) into ``--out``, reads everything back and checks it against the old files, and with ``--delete``
then removes the old files. ``--out`` must not hold a cells.jsonl yet. From the repository root:

    python -m benchmarks.convert_cells robustness OLD_FOLDER --out results/robustness [--delete]
    python -m benchmarks.convert_cells impact_robust OLD_FOLDER --out results/impact_robust [--delete]
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

from benchmarks import impact_robust, robustness
from impact_env.results_store import write_atomic

# per benchmark: the old cell files' pattern, and an old plan file's name -> its path under plans/
CELLS = {"robustness": "*__*__*.json", "impact_robust": "*__*__*__*.json"}


def old_plans(benchmark: str, folder: Path) -> dict[Path, Path]:
    """The old plan files of ``folder`` -> where they go, relative to the new folder."""
    if benchmark == "robustness":
        return {p: Path("plans") / f"{p.name.removesuffix('__plan.json')}.json"
                for p in sorted(folder.glob("*__plan.json"))}
    out = {}
    for planner in impact_robust.PLANNERS:
        for p in sorted(folder.glob(f"*__{planner}_plan.json")):
            out[p] = Path("plans") / planner / f"{p.name.removesuffix(f'__{planner}_plan.json')}.json"
    return out


def old_cells(benchmark: str, folder: Path) -> list[Path]:
    plans = set(old_plans(benchmark, folder))
    return [p for p in sorted(folder.glob(CELLS[benchmark])) if p not in plans]


def convert(benchmark: str, folder: Path, out: Path) -> tuple[list[Path], list[Path]]:
    """Write ``out``/cells.jsonl, table.md and plans/ from the old files of ``folder`` and check them; returns
    the old cell files and the old plan files (all of them checked)."""
    module = {"robustness": robustness, "impact_robust": impact_robust}[benchmark]
    cells, plans = old_cells(benchmark, folder), old_plans(benchmark, folder)
    if not cells and not plans:
        raise SystemExit(f"{folder} holds no per-cell files of the {benchmark} benchmark")
    store_path = out / "cells.jsonl"
    if store_path.exists():
        raise SystemExit(f"{store_path} exists already: convert into a folder without cells.jsonl")
    texts: dict[tuple, str] = {}
    for path in cells:
        text = path.read_text(encoding="utf-8")
        cell = json.loads(text)
        if json.dumps(cell) != text:  # the old writer's json.dumps: the text is the line, byte for byte
            raise SystemExit(f"{path}: not json.dumps of its cell (hand-edited?); convert it by hand")
        key = module.key_of(cell)
        if key in texts:
            raise SystemExit(f"{path}: a second file for the cell {key!r}")
        texts[key] = text
    ordered = module.sort_cells([json.loads(t) for t in texts.values()],
                                module.all_scenarios([json.loads(t) for t in texts.values()]))
    write_atomic(store_path, "".join(texts[module.key_of(c)] + "\n" for c in ordered))
    for old, new in plans.items():
        (out / new).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(old, out / new)
    # read back: every old cell equal, field for field and byte for byte; every plan byte for byte
    store = module.cell_store(out)
    if len(store) != len(cells):
        raise SystemExit(f"{store_path}: {len(store)} cells read back, {len(cells)} files converted")
    for path in cells:
        text = path.read_text(encoding="utf-8")
        back = store.get(module.key_of(json.loads(text)))
        if back != json.loads(text) or json.dumps(back) != text:
            raise SystemExit(f"{store_path}: the cell of {path.name} did not read back equal")
    for old, new in plans.items():
        if (out / new).read_bytes() != old.read_bytes():
            raise SystemExit(f"{out / new}: not the same bytes as {old}")
    module.write_table(out, store.cells())
    return cells, list(plans)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("benchmark", choices=sorted(CELLS))
    parser.add_argument("folder", type=Path, help="the folder of per-cell JSON files")
    parser.add_argument("--out", type=Path, required=True, help="the new folder (may be the old one)")
    parser.add_argument("--delete", action="store_true",
                        help="remove the old cell and plan files (and an old table.md) once all is checked")
    args = parser.parse_args(argv)
    cells, plans = convert(args.benchmark, args.folder, args.out)
    print(f"{args.out / 'cells.jsonl'}: {len(cells)} cells converted and checked; {len(plans)} plans in "
          f"{args.out / 'plans'}; {args.out / 'table.md'} written")
    if args.delete:
        for path in cells + plans:
            path.unlink()
        old_table = args.folder / "table.md"
        if old_table.exists() and args.folder.resolve() != args.out.resolve():
            old_table.unlink()
        if args.folder.exists() and not any(args.folder.iterdir()):
            args.folder.rmdir()
        print(f"removed the {len(cells) + len(plans)} old files of {args.folder}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
