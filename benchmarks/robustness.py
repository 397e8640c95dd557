"""Robustness benchmark: closed-loop success and robustness of the expert against the size of a perturbation.

Stacks (``ExpertConfig``): ``paper`` (the paper's stack: local replanning at planned impacts only),
``+id`` (+ online identification of restitution), ``+mission`` (+ mission-level replanning), ``all``
(identification, mission replanning and safe segments together).

Perturbations, one axis at a time around nominal, plus the combined condition:

- ``e``: the simulator's restitution off by +-level (the sign alternates with the seed, so a level has two
  distinct episodes when nothing else is random: the script runs 2 seeds there and says so);
- ``offset``: objects start uniformly within ``level`` m of their planned position;
- ``thrust``: multiplicative thrust noise of standard deviation ``level``;
- ``impact``: post-impact velocity noise (m/s per axis), where the simulator has the option
  ``impact_velocity_noise_mps``;
- ``combined``: e +-0.2, 10 cm, 10 % thrust noise.

Every cell (scenario, stack, condition) is a line of ``--out``/cells.jsonl, written atomically when the
cell is done, so an interrupted run resumes where it stopped (:mod:`impact_env.results_store`); the offline
plans are cached in ``--out``/plans/. Episodes run on the sweep engine (:mod:`impact_env.sweep`):
``--workers`` spawned processes, or Ray tasks with ``--engine ray [--address ADDR]`` (the cells are the same
either way, timings aside); a cell records its stack's config, and ``--stale STACKS`` re-flies the cells of
those stacks flown with another. Prints the markdown table (success rate, mean and min robustness, unplanned
contacts per episode, mission replans per episode and their solve time, the error of the final restitution
estimates), writes the table of every cell to ``--out``/table.md, and draws success against perturbation
size. From the repository root:

    python -m benchmarks.robustness --estimate                # how long the selected grid would take
    python -m benchmarks.robustness [--scenarios a,b] [--stacks paper,all] [--axes combined,e] [--seeds 50]
    python -m benchmarks.robustness --axes e,offset --levels e=0.4,0.5 --levels offset=0.2,0.25   # beyond
    python -m benchmarks.robustness --table-only --plot docs/img/robustness.png
    python -m benchmarks.robustness --restamp all,+mission --flown-after OLD_CELLS   # docs/robustness.md
"""

from __future__ import annotations

import argparse
import inspect
import json
import os
import time
from pathlib import Path

import numpy as np

from benchmarks import open_engine
from impact_env.results_store import CellStore, atomic_path, write_atomic
from impact_env.sweep import EngineConfig, add_engine_arguments, engine_config
from planners.expert.stacks import STACKS
from planners.expert.stacks import stack_config as expert_config

SHIPPED = ("corridor", "obstacle_avoidance", "throw_and_catch_exp", "long_throw_trim")
NEW = ("ping_pong_stop", "relay", "two_objects", "held_drift", "narrow_gap", "one_robot_two_objects", "timed_visits",
       "wall_start", "four_robots")
AXES = {"e": (0.1, 0.2, 0.3), "offset": (0.05, 0.10, 0.15), "thrust": (0.05, 0.10, 0.20),
        "impact": (0.005, 0.01, 0.02, 0.03)}
COMBINED = {"e": 0.2, "offset": 0.10, "thrust": 0.10}
RESULTS = Path(__file__).resolve().parents[1] / "results" / "robustness"  # cells.jsonl, table.md, plans/
# the stacks' config fingerprints (config_fingerprint) on main when the cells began to record theirs: a cell
# without ``config`` counts as flown with its stack's (the paper's stack has not changed since)
UNSTAMPED_CONFIG = {"paper": "3720cb004e2e", "+id": "3d61b070a04a", "+mission": "4830c6f13bd5",
                    "all": "0f8ce77b8bfd"}
# a fingerprint whose flights are those of a later one of its stack, bit for bit: a cell flown with the first counts
# as flown with the second. Issue 22's held-goal aim, way-round test and attempt budget added ExpertConfig and
# MissionConfig fields that the paper's stack sets off or has no mission layer for, so its flights did not move
# (3720cb004e2e -> e0cb7260bd3c); then the finer re-plan grid and the keep-off options (off in ``paper`` and
# ``+id``, and neither has a mission layer) moved ``paper`` and ``+id`` again. ``PlannerConfig.contact_cones``
# (None) moved ``all``'s (a5658451c33f -> 8fd8a232db00): at None the re-plans' models are the same to the bit
# ``conjunct_weight`` (0 in ``PlannerConfig`` and ``MissionConfig``: the re-plans' models unchanged) moved ``all``'s
# (8fd8a232db00 -> 5970a6b79492) and ``+mission``'s (0b1e9dfd2c02 -> 544e93092cd1). ``ExpertConfig.way_round``,
# ``MissionConfig.later_approaches`` and ``HandoverConfig.later_approaches`` (all off by default: the same
# segments, re-plans and repairs) moved all four: paper 5275d5c9b93d -> f777d71e62fc, +id 476b7a8562a8 ->
# 55ed3f5d261b, +mission 544e93092cd1 -> 1ff7ca4cde67, all 5970a6b79492 -> ec880eece4b1
SAME_FLIGHTS = {"3720cb004e2e": "f777d71e62fc", "e0cb7260bd3c": "f777d71e62fc", "5275d5c9b93d": "f777d71e62fc",
                "fc3c6319afa8": "55ed3f5d261b", "476b7a8562a8": "55ed3f5d261b",
                "a5658451c33f": "ec880eece4b1", "8fd8a232db00": "ec880eece4b1", "5970a6b79492": "ec880eece4b1",
                "0b1e9dfd2c02": "1ff7ca4cde67", "544e93092cd1": "1ff7ca4cde67"}
_WORKER: dict = {}


def _stack_name(text: str) -> str:
    """A stack as the cell files spell it too (``plus_id``), normalised to ``+id``; unknown stacks refused."""
    stack = text.replace("plus_", "+")
    if stack not in STACKS:
        raise argparse.ArgumentTypeError(f"{text!r} is not a stack: one of {', '.join(STACKS)} (or plus_id, "
                                         "plus_mission as in the cell file names)")
    return stack


def add_cell_arguments(parser: argparse.ArgumentParser, seed: bool = False) -> None:
    """The arguments that name one cell (SCENARIO STACK AXIS LEVEL, and with ``seed`` one of its episodes,
    SEED) and ``--allow-side-switches``, for the scripts that re-fly cells (:mod:`benchmarks.robustness_episode`,
    :mod:`benchmarks.robustness_reproduce`). ``args.stack`` comes normalised (``plus_id`` -> ``+id``)."""
    parser.add_argument("scenario")
    parser.add_argument("stack", type=_stack_name, help="paper, +id, +mission or all (plus_id / plus_mission "
                                                        "accepted)")
    parser.add_argument("axis", choices=("nominal", "combined", *AXES), metavar="axis",
                        help="nominal, combined, " + ", ".join(AXES))
    parser.add_argument("level", type=float)
    if seed:
        parser.add_argument("seed", type=int)
    parser.add_argument("--allow-side-switches", action="store_true",
                        help="fly mission re-plans that have a side switch, as the benchmark's cells were flown "
                             "before MissionConfig.allow_side_switches existed")


def has_impact_noise() -> bool:
    from impact_env.transport.core import TransportCore

    return "impact_velocity_noise_mps" in inspect.signature(TransportCore).parameters


def conditions(axes: list[str], levels: dict[str, tuple[float, ...]] | None = None) -> list[tuple[str, float]]:
    """The cells' conditions: nominal, then each axis at its levels (``levels`` overrides :data:`AXES`)."""
    out = [("nominal", 0.0)]
    for axis in axes:
        if axis == "combined":
            out.append(("combined", 0.0))
        elif axis == "impact" and not has_impact_noise():
            continue
        else:
            out += [(axis, level) for level in (levels or {}).get(axis, AXES[axis])]
    return out


def parse_levels(specs: list[str], axes: list[str]) -> dict[str, tuple[float, ...]]:
    """``--levels e=0.4,0.5`` (repeatable): the levels of one swept axis instead of the default ones."""
    out: dict[str, tuple[float, ...]] = {}
    for spec in specs:
        axis, _, values = spec.partition("=")
        if axis not in AXES:
            raise SystemExit(f"--levels {spec!r}: the axis must be one of {', '.join(AXES)}")
        if axis not in axes:
            raise SystemExit(f"--levels {spec!r}: add {axis} to --axes too")
        try:
            levels = tuple(float(v) for v in values.split(","))
        except ValueError:
            raise SystemExit(f"--levels {spec!r}: the levels must be numbers, e.g. {axis}=0.4,0.5") from None
        if not levels or not all(np.isfinite(v) and v > 0 for v in levels):
            raise SystemExit(f"--levels {spec!r}: the levels must be finite numbers > 0")
        out[axis] = levels
    return out


def env_options(scenario, axis: str, level: float, seed: int) -> dict:
    sign = 1.0 if seed % 2 else -1.0
    e = scenario.restitution
    if axis == "combined":
        return {"restitution": float(np.clip(e + sign * COMBINED["e"], 0, 1)),
                "initial_position_noise_m": COMBINED["offset"], "thrust_noise": COMBINED["thrust"]}
    if axis == "e":
        return {"restitution": float(np.clip(e + sign * level, 0, 1))}
    if axis == "offset":
        return {"initial_position_noise_m": level}
    if axis == "thrust":
        return {"thrust_noise": level}
    if axis == "impact":
        return {"impact_velocity_noise_mps": level}
    return {}


def cell_seeds(axis: str, seeds: int) -> int:
    """Deterministic cells need fewer seeds: nominal has one episode, the e axis two (one per sign)."""
    return {"nominal": 1, "e": min(2, seeds)}.get(axis, seeds)


def _episode(args: tuple) -> dict:
    """One episode: (scenario, stack, plan as a dict, axis, level, seed[, config]) -> what it did. ``config``, an
    ``ExpertConfig`` flown instead of the stack's (``stack`` then only names it in the worker's cache of experts,
    e.g. :mod:`benchmarks.conjunct_weight`'s variants)."""
    scenario_name, stack, plan_dict, axis, level, seed, *given = args
    from impact_env.rollout import robot_object_impacts, run_episode
    from impact_env.transport.gym_env import TransportEnv
    from impact_env.transport.scenario import load_scenario
    from planners.expert import Expert
    from planners.plan import Plan

    key = (scenario_name, stack)
    if key not in _WORKER:  # one expert (compiled MPCs) per worker, scenario and stack
        _WORKER[key] = Expert(load_scenario(scenario_name), plan=Plan.from_dict(plan_dict),
                              config=given[0] if given else expert_config(stack))
    expert = _WORKER[key]
    options = env_options(expert.scenario, axis, level, seed)
    env = TransportEnv(expert.scenario, **options)
    res = run_episode(env, expert, seed=seed)
    report = expert.report()
    simulated = options.get("restitution", expert.scenario.restitution)
    mission = report.get("mission", {})
    solves = [r["solve_s"] for r in mission.get("records", [])]
    robots = {r.name for r in expert.scenario.robots}
    unplanned = report["unplanned_contacts"]
    return {"seed": seed, "success": bool(res.success), "robustness": float(res.robustness),
            "impacts": len(robot_object_impacts(expert.scenario, res.impacts)),
            "unplanned": sum(unplanned.values()),
            "robot_contacts": sum(v for k, v in unplanned.items()
                                  if any(p in robots for p in k.split("-"))
                                  and not any(o.name in k.split("-") for o in expert.scenario.objects)),
            "unplanned_pairs": unplanned, "mission_replans": mission.get("replans", 0),
            "mission_attempts": mission.get("attempts", 0), "mission_timeouts": mission.get("timeouts", 0),
            "replan_solve_s": solves, "identification": identification_record(expert, simulated),
            "wall_s": res.wall_time_s}


def identification_record(expert, simulated: float) -> dict | None:
    """Per robot-object pair, the restitution the expert's contact inverse ended the episode with (its
    identified estimate, or the file's where it kept that) and its ``error`` against the ``simulated`` one;
    None for a stack without identification."""
    if expert.config.identification is None:
        return None
    ident = expert.identifier
    return {f"{r.name}-{o.name}": {"estimate": ident.restitution_for(r.name, o.name),
                                   "error": ident.restitution_for(r.name, o.name) - simulated}
            for r in expert.scenario.robots for o in expert.scenario.objects}


def fingerprinted_config(config) -> dict:
    """What a config fingerprint names: every field of the ``ExpertConfig`` (nested configs included) and, for a
    stack that re-plans the mission, the planner configs its online layer builds with their defaults (mission
    re-plans and station-keeping trims: ``PlannerConfig()``, the ``IRPlannerConfig`` of an impact-robust
    re-plan, the ``HandoverConfig`` inside it), which ``ExpertConfig`` does not hold. A stack without mission
    re-plans plans nothing online, so its record is its ``ExpertConfig`` alone, as before that was added."""
    import dataclasses

    record = dataclasses.asdict(config)
    if config.mission is not None:
        from planners.offline.config import IRPlannerConfig, PlannerConfig

        record["planner_defaults"] = {"PlannerConfig": dataclasses.asdict(PlannerConfig()),
                                      "IRPlannerConfig": dataclasses.asdict(IRPlannerConfig())}
    return record


def fingerprint(record: dict) -> str:
    """12 hex digits of a JSON record (keys sorted; anything JSON lacks by its ``repr``)."""
    import hashlib

    text = json.dumps(record, sort_keys=True, default=repr)
    return hashlib.sha256(text.encode()).hexdigest()[:12]


def config_fingerprint(stack: str) -> str:
    """12 hex digits naming the stack's config as it is now (:func:`fingerprinted_config`: the ``ExpertConfig``
    and the planner defaults its re-plans use): a cell records the one it was flown with (``config``), and
    ``--stale`` re-flies the cells whose config differs. It names the options, not the code: a change of code
    under the same options keeps it."""
    return fingerprint(fingerprinted_config(expert_config(stack)))


def expert_only_fingerprint(stack: str) -> str:
    """The fingerprint the stack's config has under the formula before the planner defaults were added to it
    (the ``ExpertConfig`` alone): what the cells flown before then recorded. :func:`restamp` reads it."""
    import dataclasses

    return fingerprint(dataclasses.asdict(expert_config(stack)))


def restamp(store: CellStore, fingerprints: dict[str, tuple[str, str]], flown=None,
            before: CellStore | None = None) -> list[dict]:
    """Give the cells of ``store`` whose config is a stack's old fingerprint its new one, in one atomic rewrite.

    ``fingerprints`` maps a stack to ``(old, new)``; a cell of that stack flown with ``old`` (``flown(cell)``,
    default :func:`flown_with`: a cell without a ``config`` counts as flown with :data:`UNSTAMPED_CONFIG`'s) is
    stamped ``new``, and records the ``old`` one as ``restamped_from``. Other cells are left byte for byte.
    Returns the cells changed.

    This asserts that those cells were flown under what ``new`` names, so the part of the config ``old`` does
    not name must be the same now as when they were flown. ``before``: the cells as they were when that part
    last changed (e.g. the file at that commit); a cell whose first episode is the one it had there was
    flown, at least in part, before the change, and is left as it is. Run it while nothing else writes the
    file."""
    flown = flown or flown_with
    changed = []
    for cell in store.cells():
        pair = fingerprints.get(cell["stack"])
        if pair is None or pair[0] == pair[1] or flown(cell) != pair[0]:
            continue
        earlier = None if before is None else before.get(store.key(cell))
        if earlier is not None and earlier["episodes"][:1] == cell["episodes"][:1]:
            continue
        changed.append({**cell, "config": pair[1], "restamped_from": pair[0]})
    store.put_many(changed)
    return changed


def restamp_expert_only(store: CellStore, stacks, new_of=None, old_of=None, flown=None,
                        before: CellStore | None = None) -> list[dict]:
    """:func:`restamp` from the formula before the planner defaults joined the fingerprint to today's: the cells
    of ``stacks`` flown with the stack's config of today under the old formula (the ``ExpertConfig`` alone)
    get its fingerprint under today's, but for those ``before`` holds already (flown before the planner
    defaults last changed). ``new_of`` / ``old_of`` / ``flown``: the benchmark's own fingerprint functions of a
    stack and of a cell (default: this module's)."""
    new_of = new_of or config_fingerprint
    old_of = old_of or expert_only_fingerprint
    return restamp(store, {stack: (old_of(stack), new_of(stack)) for stack in stacks}, flown, before)


def cell_key(scenario: str, stack: str, axis: str, level: float) -> tuple[str, str, str, str]:
    """What names a cell: the level as ``:g`` prints it (the name of the per-cell file a cell had before)."""
    return scenario, stack, axis, f"{level:g}"


def key_of(cell: dict) -> tuple[str, str, str, str]:
    """A cell's key in cells.jsonl (:func:`cell_key` of its fields)."""
    return cell_key(cell["scenario"], cell["stack"], cell["axis"], cell["level"])


def cell_store(out: Path) -> CellStore:
    """The benchmark's cells in ``out``/cells.jsonl. Per-cell JSON files of an older version in ``out`` are
    refused with the command that converts them."""
    path = out / "cells.jsonl"
    if not path.exists() and any(out.glob("*__*__*.json")):
        raise SystemExit(f"{out} holds per-cell JSON files (the format before cells.jsonl): convert them "
                         f"first with python -m benchmarks.convert_cells robustness {out} --out {out}")
    return CellStore(path, key=key_of)


def plan_path(out: Path, scenario_name: str) -> Path:
    """Where the benchmark caches a scenario's offline plan (a plan file: ``Plan.load`` reads it)."""
    return out / "plans" / f"{scenario_name}.json"


def load_cell(out: Path, scenario: str, stack: str, axis: str, level: float) -> dict:
    """One cell of ``out``/cells.jsonl; SystemExit naming the cell if it was not run."""
    cell = cell_store(out).get(cell_key(scenario, stack, axis, level))
    if cell is None:
        raise SystemExit(f"{out / 'cells.jsonl'} has no cell {scenario} / {stack} / {axis} {level:g}")
    return cell


def plan_for(scenario_name: str, out: Path) -> dict:
    """The offline plan of a scenario, computed once and cached beside the cells (deterministic planner). A
    folder of the layout before cells.jsonl (``<scenario>__plan.json`` beside the cells) is read as it is."""
    from impact_env.transport.scenario import load_scenario
    from planners.offline.spatially_robust import plan_spatially_robust

    path = plan_path(out, scenario_name)
    old = out / f"{scenario_name}__plan.json"
    for cached in (path, old):
        if cached.exists():
            return json.loads(cached.read_text())
    plan = plan_spatially_robust(load_scenario(scenario_name))
    with atomic_path(path) as tmp:  # a kill while saving leaves no half plan to resume from
        plan.save(tmp)
    return plan.to_dict()


def run(scenarios, stacks, axes, seeds_shipped, seeds_new, out: Path, engine: EngineConfig,
        levels: dict[str, tuple[float, ...]] | None = None, stale: tuple[str, ...] = ()) -> None:
    """Fly the cells of the grid that are not done. A cell is done when it has the episodes asked for; one with
    fewer gets the missing seeds flown and added (an episode depends on its seed only, tested in
    ``tests/planners/expert/test_determinism.py``). For the stacks in ``stale``, a cell flown with another
    config than the stack's current one (:func:`config_fingerprint`; a cell from before the cells recorded it
    counts as another) is flown again whole."""
    out.mkdir(parents=True, exist_ok=True)
    store = cell_store(out)
    fingerprints = {stack: config_fingerprint(stack) for stack in stacks}
    with open_engine(engine) as pool:
        for name in scenarios:
            plan = plan_for(name, out)
            seeds = seeds_shipped if name in SHIPPED else seeds_new
            for axis, level in conditions(axes, levels):
                for stack in stacks:
                    n = cell_seeds(axis, seeds)
                    done = store.get(cell_key(name, stack, axis, level))
                    if done is not None and stack in stale and counts_as(done) != fingerprints[stack]:
                        done = None
                    if done is not None and done["episodes_requested"] >= n:
                        continue
                    kept = [] if done is None else done["episodes"][:n]
                    start = time.perf_counter()
                    jobs = [(name, stack, plan, axis, level, s) for s in range(len(kept), n)]
                    episodes = kept + list(pool.map(_episode, jobs))
                    wall = time.perf_counter() - start + (0.0 if done is None else done["wall_s"])
                    store.put({"scenario": name, "stack": stack, "axis": axis, "level": level,
                               "episodes_requested": n, "episodes": episodes, "wall_s": wall,
                               "config": fingerprints[stack]})
                    print(row(store.get(cell_key(name, stack, axis, level))), flush=True)
                    write_table(out, store.cells())


def add_restamp_arguments(parser: argparse.ArgumentParser) -> None:
    """``--restamp STACKS`` and ``--flown-after CELLS_JSONL`` (both benchmarks; :func:`restamp`)."""
    parser.add_argument("--restamp", default="", metavar="STACKS",
                        help="stamp the cells of these stacks flown with today's config under the fingerprint "
                             "before the planner defaults joined it with today's fingerprint, and stop "
                             "(docs/robustness.md#config-fingerprints)")
    parser.add_argument("--flown-after", type=Path, metavar="CELLS_JSONL",
                        help="with --restamp: the cells file as it was when the planner defaults last changed "
                             "(e.g. git show COMMIT:results/robustness/cells.jsonl); its cells not flown again "
                             "since are not restamped")


def restamp_report(changed: list[dict], out: Path) -> str:
    """What :func:`restamp` did, per stack and old -> new fingerprint."""
    counts: dict[tuple[str, str, str], int] = {}
    for cell in changed:
        key = (cell["stack"], cell["restamped_from"], cell["config"])
        counts[key] = counts.get(key, 0) + 1
    lines = [f"{n} cells of {stack}: {old} -> {new}" for (stack, old, new), n in counts.items()]
    return "\n".join(lines + [f"restamped {len(changed)} cells of {out / 'cells.jsonl'}"])


def flown_with(cell: dict) -> str | None:
    """The config fingerprint a cell was flown with (:data:`UNSTAMPED_CONFIG` for a cell that has none)."""
    return cell.get("config", UNSTAMPED_CONFIG.get(cell["stack"]))


def same_flights(fingerprint: str | None) -> str | None:
    """The fingerprint whose flights those of ``fingerprint`` are (:data:`SAME_FLIGHTS`; itself if none)."""
    return SAME_FLIGHTS.get(fingerprint, fingerprint) if fingerprint is not None else None


def counts_as(cell: dict) -> str | None:
    """The fingerprint whose flights a cell's are: :func:`flown_with`, through :data:`SAME_FLIGHTS`."""
    return same_flights(flown_with(cell))


def identification_error(cell: dict) -> str:
    """``mean / max`` over the cell's episodes of the largest |error| of an episode's final restitution
    estimates (:func:`identification_record`); ``-`` when the cell has none (no identification, or flown
    before the episodes recorded it)."""
    worst = [max(abs(p["error"]) for p in e["identification"].values()) for e in cell["episodes"]
             if e.get("identification")]
    return f"{np.mean(worst):.3f} / {max(worst):.3f}" if worst else "-"


def row(cell: dict) -> str:
    eps = cell["episodes"]
    rho = [e["robustness"] for e in eps]
    solves = [s for e in eps for s in e["replan_solve_s"]]
    label = condition_label(cell["axis"], cell["level"])
    solve = f"{np.median(solves):.1f} / {max(solves):.1f}" if solves else "-"
    stack = cell["stack"] if counts_as(cell) == config_fingerprint(cell["stack"]) else f"{cell['stack']} *"
    return (f"| {cell['scenario']} | {label} | {stack} | {len(eps)} | "
            f"{100 * np.mean([e['success'] for e in eps]):.0f}% | {np.mean(rho):+.3f} ({min(rho):+.3f}) | "
            f"{np.mean([e['robot_contacts'] for e in eps]):.2f} | {np.mean([e['mission_replans'] for e in eps]):.2f} | "
            f"{solve} | {identification_error(cell)} |")


def condition_label(axis: str, level: float) -> str:
    return {"nominal": "nominal", "combined": "e +-0.2, 10 cm, 10 % thrust", "e": f"e +-{level:g}",
            "offset": f"start within {100 * level:g} cm", "thrust": f"thrust noise {100 * level:g} %",
            "impact": f"impact noise {level:g} m/s"}[axis]


def load_cells(out: Path) -> list[dict]:
    return cell_store(out).cells()


def sort_cells(cells: list[dict], scenarios) -> list[dict]:
    """The table's order: scenario (as listed, others after), condition, level, stack."""
    order = {s: i for i, s in enumerate(STACKS)}
    axes = ["nominal", "combined", "e", "offset", "thrust", "impact"]
    return sorted(cells, key=lambda c: (list(scenarios).index(c["scenario"]) if c["scenario"] in scenarios else 99,
                                        axes.index(c["axis"]), c["level"], order[c["stack"]]))


def table(cells: list[dict], scenarios) -> str:
    lines = ["| scenario | simulator | stack | episodes | success | robustness mean (min) | robot contacts / ep | "
             "mission replans / ep | replan solve s median / max | e error mean / max |",
             "|---|---|---|---:|---:|---:|---:|---:|---:|---:|"]
    rows = [row(c) for c in sort_cells(cells, scenarios) if c["scenario"] in scenarios]
    note = (["", "\\* flown with an earlier config of the stack (`--stale STACK` flies it again)"]
            if any(" * |" in r for r in rows) else [])
    return "\n".join(lines + rows + note)


def all_scenarios(cells: list[dict]) -> list[str]:
    """The shipped and new scenarios, then any other scenario of the cells (in the order first seen)."""
    names = list(SHIPPED + NEW)
    return names + [n for n in dict.fromkeys(c["scenario"] for c in cells) if n not in names]


def write_table(out: Path, cells: list[dict]) -> Path:
    """``out``/table.md: the table of every cell (atomically, as the cells)."""
    return write_atomic(out / "table.md", table(cells, all_scenarios(cells)) + "\n")


def plot(cells: list[dict], scenarios, path: str) -> None:
    """One row per scenario: success of each stack under the combined condition (bars), then success against
    the size of each perturbation swept (one line per stack, level 0 = nominal)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    axes_names = [a for a in ("e", "offset", "thrust", "impact") if any(c["axis"] == a for c in cells)]
    scenarios = [s for s in scenarios if any(c["scenario"] == s for c in cells)]
    ncols = 1 + len(axes_names)
    fig, grid = plt.subplots(len(scenarios), ncols, figsize=(3.0 * ncols, 2.2 * len(scenarios)), squeeze=False)
    units = {"e": "restitution error +-", "offset": "start offset (m)", "thrust": "thrust noise (std)",
             "impact": "post-impact noise (m/s)"}
    colours = dict(zip(STACKS, ("tab:gray", "tab:blue", "tab:orange", "tab:green")))

    def success(cell: dict) -> float:
        return 100 * float(np.mean([e["success"] for e in cell["episodes"]]))

    legend_done = False
    for i, name in enumerate(scenarios):
        ax = grid[i, 0]
        combined = {c["stack"]: c for c in cells if c["scenario"] == name and c["axis"] == "combined"}
        stacks = [st for st in STACKS if st in combined]
        ax.bar(range(len(stacks)), [success(combined[st]) for st in stacks], color=[colours[st] for st in stacks])
        ax.set_xticks(range(len(stacks)), stacks, fontsize=7)
        ax.set_ylim(0, 105)
        ax.set_ylabel(f"{name}\nsuccess %", fontsize=8)
        if i == 0:
            ax.set_title("e +-0.2, 10 cm, 10 % thrust", fontsize=8)
        for j, axis in enumerate(axes_names, start=1):
            ax = grid[i, j]
            for stack in STACKS:
                pts = [(0.0, c) for c in cells
                       if c["scenario"] == name and c["stack"] == stack and c["axis"] == "nominal"]
                pts += [(c["level"], c) for c in cells if c["scenario"] == name and c["stack"] == stack
                        and c["axis"] == axis]
                if len(pts) < 2:
                    continue
                pts.sort(key=lambda p: p[0])
                ax.plot([p[0] for p in pts], [success(p[1]) for p in pts], marker="o", label=stack,
                        color=colours[stack])
            ax.set_ylim(-5, 105)
            if i == len(scenarios) - 1:
                ax.set_xlabel(units[axis], fontsize=8)
            if not ax.lines:
                ax.text(0.5, 0.5, "not run", ha="center", va="center", transform=ax.transAxes, fontsize=8)
                ax.set_xticks([])
            elif not legend_done:
                ax.legend(fontsize=7)
                legend_done = True
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)


def estimate(scenarios, stacks, axes, seeds_shipped, seeds_new, levels=None) -> float:
    """Seconds of one worker for the selected grid, from each scenario's episode length (a rough cost of
    2.5 ms of controller and 0.5 ms of simulation per control step and robot pair, measured here)."""
    from impact_env.transport.scenario import load_scenario

    total = 0.0
    for name in scenarios:
        sc = load_scenario(name)
        steps = round(sc.formula.horizon_s / sc.control_period_s)
        per_episode = steps * (1.5e-3 * len(sc.robots) + 0.5e-3)
        seeds = seeds_shipped if name in SHIPPED else seeds_new
        n = sum(cell_seeds(axis, seeds) for axis, _ in conditions(axes, levels)) * len(stacks)
        total += n * per_episode
    return total


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenarios", default=",".join(SHIPPED + NEW))
    parser.add_argument("--stacks", default=",".join(STACKS))
    parser.add_argument("--axes", default="combined,e,offset,thrust,impact")
    parser.add_argument("--seeds", type=int, default=50, help="seeds per random cell, shipped scenarios")
    parser.add_argument("--seeds-new", type=int, default=20, help="seeds per random cell, the new scenarios")
    add_engine_arguments(parser, default_workers=min(2, os.cpu_count() or 1))
    parser.add_argument("--levels", action="append", default=[], metavar="AXIS=L1,L2",
                        help="levels of a swept axis instead of the default ones, e.g. e=0.4,0.5 (repeatable)")
    parser.add_argument("--out", default=str(RESULTS),
                        help="the cells (cells.jsonl), their table (table.md) and the cached plans (plans/) "
                             "(default: %(default)s)")
    parser.add_argument("--stale", default="", metavar="STACKS",
                        help="comma-separated stacks whose cells flown with another config than the stack's "
                             "current one are flown again (e.g. after a default changed)")
    add_restamp_arguments(parser)
    parser.add_argument("--estimate", action="store_true", help="print the estimated time and stop")
    parser.add_argument("--table-only", action="store_true",
                        help="print the table of the cells done (and rewrite table.md); fly nothing")
    parser.add_argument("--plot", help="draw success against perturbation size to this PNG")
    args = parser.parse_args()
    scenarios, stacks, axes = args.scenarios.split(","), args.stacks.split(","), args.axes.split(",")
    out = Path(args.out)
    if args.restamp:
        try:
            restamped = tuple(_stack_name(st) for st in args.restamp.split(",") if st)
        except argparse.ArgumentTypeError as err:
            parser.error(f"--restamp: {err}")
        before = None if args.flown_after is None else CellStore(args.flown_after, key_of)
        print(restamp_report(restamp_expert_only(cell_store(out), restamped, before=before), out))
        return
    levels = parse_levels(args.levels, axes)
    if args.estimate:
        seconds = estimate(scenarios, stacks, axes, args.seeds, args.seeds_new, levels)
        print(f"about {seconds / 3600:.1f} h of one worker, {seconds / 3600 / args.workers:.1f} h with "
              f"{args.workers} workers on an idle machine")
        return
    if not args.table_only:
        if "impact" in axes and not has_impact_noise():
            print("the simulator has no impact_velocity_noise_mps option yet: the impact axis is left out")
        try:
            stale = tuple(_stack_name(st) for st in args.stale.split(",") if st)
        except argparse.ArgumentTypeError as err:
            parser.error(f"--stale: {err}")
        run(scenarios, stacks, axes, args.seeds, args.seeds_new, out, engine_config(args), levels, stale)
    cells = load_cells(out)
    if cells:
        write_table(out, cells)
    print(table(cells, scenarios))
    if args.plot:
        plot(cells, scenarios, args.plot)
        print(f"wrote {args.plot}")


if __name__ == "__main__":
    main()
