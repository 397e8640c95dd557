"""Closed-loop benchmark: the expert flying the spatially robust (SR) plan against the impact-robust (IR) plan.

For each scenario both plans are made once (cached in ``--out``/plans/sr/ and plans/ir/) and flown by the
expert in the Gymnasium env under:

- post-impact velocity noise (``impact_velocity_noise_mps``) of 0, delta, 2 delta and 5 delta m/s, delta being
  the IR plan's delta on that scenario (the same noise in m/s for both plans): 50 seeds per cell (the
  noise-free cell is deterministic and runs once);
- the simulator's restitution off by -0.2, -0.1, +0.1, +0.2 (no noise: each is one deterministic episode).

Expert stacks: ``all`` (the default :class:`~planners.expert.ExpertConfig`: identification, mission
replanning, safe segments; a mission re-plan of an IR plan is an IR plan where the planner finds delta > 0,
``MissionConfig.impact_robust_replans``), ``paper``
(local replanning at planned impacts only, so what each plan brings is what flies) and, on request,
``all+sig`` (``all`` with identification's significance test, k = 3, which keeps the file's restitution
unless the impacts contradict it). An IR plan is flown with its copies as contingency plans
(:mod:`planners.online.contingency`).

Reported per cell: success rate (final STL robustness > 0), mean and min robustness, the object's final
speed (mean and max, m/s), the share of episodes whose object ends inside the final box around its plan's
final state (the scenario's ``[final_box]``, default 0.5 m / 0.05 m/s: the residual the IR plan tolerates),
mission re-plans per episode, and the final restitution estimates' error against the simulated one (per
episode the largest over the pairs; ``-`` for a stack without identification or a cell flown before the
episodes recorded it; :func:`benchmarks.robustness.identification_record`). Every cell is a line of
``--out``/cells.jsonl, written atomically when the cell is done (a rerun resumes;
:mod:`impact_env.results_store`), the table of every cell goes to ``--out``/table.md and the successes of
the current cells to ``--out``/summary.md (:func:`summary`); episodes run in
``--workers`` spawned processes. A cell records the fingerprint of its
stack's config (``config``, as in :mod:`benchmarks.robustness`; a cell without one was flown before 0.4), and
``--stale STACKS`` flies those cells again whose config is not the stack's current one; ``--factors`` and
``--planners`` fly a part of the grid. A cell records the plan it flew (``plan``, :func:`plan_fingerprint`);
a cell of another plan than the cached one is flown again, and marked in the table. ``--restamp STACKS``
moves cells to today's fingerprint formula (docs/robustness.md#config-fingerprints). From the repository root:

    python -m benchmarks.impact_robust --estimate
    python -m benchmarks.impact_robust [--scenarios a,b] [--stacks all,paper,all+sig] [--seeds 50] [--workers 2]
    python -m benchmarks.impact_robust --factors 1 --planners ir --stale all,paper   # the guarantee, re-flown
    python -m benchmarks.impact_robust --table-only
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from benchmarks.robustness import (
    add_restamp_arguments,
    fingerprint,
    fingerprinted_config,
    identification_error,
    identification_record,
    restamp_expert_only,
    restamp_report,
    same_flights,
)
from impact_env.results_store import CellStore, atomic_path, write_atomic

RESULTS = Path(__file__).resolve().parents[1] / "results" / "impact_robust"  # cells.jsonl, table.md, plans/
# every shipped scenario where the impact-robust planner finds delta > 0: the paper's and their kin (ping_pong_stop,
# relay and two_objects since min_robustness_m), and the newer ones of benchmarks.robustness (wall_start,
# narrow_gap, held_drift, four_robots); one_robot_two_objects and timed_visits have none
# (docs/robustness.md#the-guarantee-on-the-newer-scenarios)
SHIPPED = ("corridor", "obstacle_avoidance", "throw_and_catch_exp", "long_throw_trim", "ping_pong_stop", "relay",
           "two_objects", "wall_start", "narrow_gap", "held_drift", "four_robots")
PLANNERS = ("sr", "ir")
STACKS = ("all", "paper", "all+sig")
DEFAULT_STACKS = ("all", "paper")
NOISE_FACTORS = (1.0, 2.0, 5.0)
E_OFFSETS = (-0.2, -0.1, 0.1, 0.2)
_WORKER: dict = {}


def expert_config(stack: str):
    from planners.expert import ExpertConfig
    from planners.online.identification import IdentificationConfig

    return {"all": ExpertConfig(), "paper": ExpertConfig.paper(),
            "all+sig": ExpertConfig(identification=IdentificationConfig(significance=3))}[stack]


def config_fingerprint(stack: str) -> str:
    """12 hex digits naming the stack's config as it is now (:func:`benchmarks.robustness.config_fingerprint`
    of the same config: the ``ExpertConfig`` and the planner defaults its re-plans use): a cell records the
    one it was flown with."""
    return fingerprint(fingerprinted_config(expert_config(stack)))


def expert_only_fingerprint(stack: str) -> str:
    """The stack's fingerprint under the formula before the planner defaults joined it (the cells flown before
    then recorded it; :func:`benchmarks.robustness.restamp`)."""
    import dataclasses

    return fingerprint(dataclasses.asdict(expert_config(stack)))


def restamp(store: CellStore, stacks, before: CellStore | None = None) -> list[dict]:
    """:func:`benchmarks.robustness.restamp_expert_only` with this benchmark's stacks: a cell without a config
    (flown before 0.4) is not restamped (it counts as another config here)."""
    return restamp_expert_only(store, stacks, config_fingerprint, expert_only_fingerprint,
                               flown=lambda cell: cell.get("config"), before=before)


def plan_path(out: Path, name: str, planner: str) -> Path:
    """Where a scenario's SR or IR plan is cached (a plan file: ``Plan.load`` reads it)."""
    return out / "plans" / planner / f"{name}.json"


def conditions(delta: float, seeds: int, factors=None) -> list[tuple[str, float, int]]:
    """(axis, level, episodes): noise levels in m/s, restitution offsets; with ``factors`` (multiples of
    delta) only those noise cells."""
    if factors is not None:
        return [("noise", k * delta, seeds) for k in factors]
    out = [("nominal", 0.0, 1)]
    out += [("noise", k * delta, seeds) for k in NOISE_FACTORS]
    out += [("e", de, 1) for de in E_OFFSETS]
    return out


def plans_for(name: str, out: Path) -> dict[str, dict]:
    """Both offline plans of a scenario, computed once and cached (the planners are deterministic)."""
    from impact_env.transport.scenario import load_scenario
    from planners.offline.impact_robust import IRPlannerConfig, plan_impact_robust
    from planners.offline.spatially_robust import plan_spatially_robust

    plans = {}
    for planner in PLANNERS:
        path = plan_path(out, name, planner)
        if not path.exists():
            scenario = load_scenario(name)
            plan = (plan_impact_robust(scenario, IRPlannerConfig(time_limit_s=600)) if planner == "ir"
                    else plan_spatially_robust(scenario))
            with atomic_path(path) as tmp:  # a kill while saving leaves no half plan to resume from
                plan.save(tmp)
        plans[planner] = json.loads(path.read_text())
    return plans


def _episode(args: tuple) -> dict:
    name, planner, stack, plan_dict, axis, level, seed = args
    from impact_env.rollout import robot_object_impacts, run_episode
    from impact_env.transport.gym_env import TransportEnv
    from impact_env.transport.scenario import load_scenario
    from planners.expert import Expert
    from planners.offline.impact_robust import final_boxes
    from planners.plan import Plan

    key = (name, planner, stack)
    if key not in _WORKER:  # one expert (compiled MPCs) per worker, scenario, plan and stack
        _WORKER[key] = Expert(load_scenario(name), plan=Plan.from_dict(plan_dict), config=expert_config(stack))
    expert = _WORKER[key]
    sc = expert.scenario
    options = {}
    if axis == "noise":
        options["impact_velocity_noise_mps"] = level
    elif axis == "e":
        options["restitution"] = float(np.clip(sc.restitution + level, 0.0, 1.0))
    env = TransportEnv(sc, **options)
    res = run_episode(env, expert, seed=seed)
    simulated = options.get("restitution", sc.restitution)
    report = expert.report()
    plan, boxes = expert.offline_plan, final_boxes(sc)
    dt = sc.control_period_s
    finals = {}
    for i, o in enumerate(sc.objects):
        k = len(sc.robots) + i
        p_end = res.positions[-1, k]
        v_end = (res.positions[-1, k] - res.positions[-2, k]) / dt
        tf = res.times_s[-1]
        dp = np.abs(p_end - plan.position(o.name, tf))
        dv = np.abs(v_end - plan.bodies[o.name].segments[-1].velocity(plan.tf_s)[0])
        (bp, bv) = boxes[o.name]
        finals[o.name] = {"speed": float(np.hypot(*v_end)), "in_box": bool(np.all(dp <= bp) and np.all(dv <= bv))}
    return {"seed": seed, "success": bool(res.success), "robustness": float(res.robustness),
            "impacts": len(robot_object_impacts(sc, res.impacts)),
            "final_speed": max(f["speed"] for f in finals.values()),
            "in_final_box": all(f["in_box"] for f in finals.values()),
            "mission_replans": report.get("mission", {}).get("replans", 0),
            "identification": identification_record(expert, simulated), "wall_s": res.wall_time_s}


def cell_key(name: str, planner: str, stack: str, axis: str, level: float) -> tuple[str, str, str, str, str]:
    """What names a cell: the level exactly (``repr`` of the float, -0.0 as 0.0). A noise level is a multiple
    of the plan's delta, so two plans whose deltas differ by less than 5e-5 m/s (the 4 decimals of the
    per-cell file names the key kept before) would share a key: the new plan's cell would be taken as done."""
    return name, planner, stack, axis, repr(float(level) + 0.0)


def key_of(cell: dict) -> tuple[str, str, str, str, str]:
    """A cell's key in cells.jsonl (:func:`cell_key` of its fields)."""
    return cell_key(cell["scenario"], cell["planner"], cell["stack"], cell["axis"], cell["level"])


def cell_store(out: Path) -> CellStore:
    """The benchmark's cells in ``out``/cells.jsonl. Per-cell JSON files of an older version in ``out`` are
    refused with the command that converts them."""
    path = out / "cells.jsonl"
    if not path.exists() and any(out.glob("*__*__*__*.json")):
        raise SystemExit(f"{out} holds per-cell JSON files (the format before cells.jsonl): convert them "
                         f"first with python -m benchmarks.convert_cells impact_robust {out} --out {out}")
    return CellStore(path, key=key_of)


def run(scenarios, stacks, seeds: int, out: Path, workers: int, factors=None, planners=PLANNERS,
        stale: tuple[str, ...] = ()) -> None:
    """Fly the cells not done (``factors``: only those noise cells; ``planners``: only those plans). A cell with
    fewer episodes than asked gets the missing seeds flown and added (an episode depends on its seed only). A
    cell flown with another plan than the cached one (:func:`plan_fingerprint`, recorded as ``plan``) is flown
    again whole; so is, for the stacks in ``stale``, a cell flown with another config than the stack's current
    one (or none recorded)."""
    out.mkdir(parents=True, exist_ok=True)
    store = cell_store(out)
    fingerprints = {stack: config_fingerprint(stack) for stack in stacks}
    ctx = multiprocessing.get_context("spawn")  # the parent has run HiGHS threads: never fork after that
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as pool:
        for name in scenarios:
            plans = plans_for(name, out)
            delta = plans["ir"]["delta_mps"]
            flown = {planner: plan_fingerprint(plans[planner]) for planner in planners}
            for axis, level, n in conditions(delta, seeds, factors):
                for stack in stacks:
                    for planner in planners:
                        done = store.get(cell_key(name, planner, stack, axis, level))
                        if (done is not None and stack in stale
                                and same_flights(done.get("config")) != fingerprints[stack]):
                            done = None
                        if done is not None and done.get("plan", flown[planner]) != flown[planner]:
                            done = None  # another plan with the same delta
                        if done is not None and done["episodes_requested"] >= n:
                            continue
                        kept = [] if done is None else done["episodes"][:n]  # a cell asked for more seeds
                        start = time.perf_counter()
                        jobs = [(name, planner, stack, plans[planner], axis, level, s) for s in range(len(kept), n)]
                        episodes = kept + list(pool.map(_episode, jobs))
                        wall = time.perf_counter() - start + (0.0 if done is None else done["wall_s"])
                        cell = {"scenario": name, "planner": planner, "stack": stack, "axis": axis, "level": level,
                                "delta": delta, "episodes_requested": n, "episodes": episodes, "wall_s": wall,
                                "config": fingerprints[stack], "plan": flown[planner]}
                        store.put(cell)
                        print(row(cell), flush=True)
                        write_table(out, store.cells())


def label(cell: dict) -> str:
    if cell["axis"] == "nominal":
        return "nominal"
    if cell["axis"] == "noise":
        return f"impact noise {cell['level'] / cell['delta']:g} delta ({cell['level']:.4g} m/s)"
    return f"e {cell['level']:+g}"


def flown_with_todays_config(cell: dict) -> bool:
    """Whether the cell was flown with its stack's config as it is now (through ``same_flights``; a cell without a
    config was flown with another one)."""
    return same_flights(cell.get("config")) == config_fingerprint(cell["stack"])


def flown_with_todays_plan(cell: dict, delta: float | None, plan: str | None) -> bool:
    """Whether the cell was flown at the IR plan's delta now and with its planner's plan now (``None``: not
    known, not held against it; a cell that recorded no plan counts as flying today's)."""
    return not ((delta is not None and cell["delta"] != delta) or (plan is not None and cell.get("plan", plan) != plan))


def row(cell: dict, delta: float | None = None, plan: str | None = None) -> str:
    """A cell's table row; ``delta``: the scenario's IR plan's delta now, ``plan``: the fingerprint of the plan
    the cell's planner has now (a cell flown at another delta, or with another plan where it recorded one, is
    marked with a dagger)."""
    eps = cell["episodes"]
    rho = [e["robustness"] for e in eps]
    speed = [e["final_speed"] for e in eps]
    stack = cell["stack"] if flown_with_todays_config(cell) else f"{cell['stack']} *"
    if not flown_with_todays_plan(cell, delta, plan):
        stack += " †"
    return (f"| {cell['scenario']} | {label(cell)} | {stack} | {cell['planner']} | {len(eps)} | "
            f"{100 * np.mean([e['success'] for e in eps]):.0f}% | {np.mean(rho):+.3f} ({min(rho):+.3f}) | "
            f"{np.mean(speed):.3f} ({max(speed):.3f}) | {100 * np.mean([e['in_final_box'] for e in eps]):.0f}% | "
            f"{np.mean([e['mission_replans'] for e in eps]):.2f} | {identification_error(cell)} |")


def sort_cells(cells: list[dict], scenarios) -> list[dict]:
    """The cells of ``scenarios`` in the table's order: scenario (as listed), condition, level, stack, plan."""
    axes = ["nominal", "noise", "e"]
    cells = [c for c in cells if c["scenario"] in scenarios]
    return sorted(cells, key=lambda c: (list(scenarios).index(c["scenario"]), axes.index(c["axis"]), c["level"],
                                        STACKS.index(c["stack"]), PLANNERS.index(c["planner"])))


def all_scenarios(cells: list[dict]) -> list[str]:
    """The shipped scenarios, then any other scenario of the cells (in the order first seen)."""
    return list(SHIPPED) + [n for n in dict.fromkeys(c["scenario"] for c in cells) if n not in SHIPPED]


def table(cells: list[dict], scenarios, deltas: dict[str, float] | None = None,
          plans: dict[tuple[str, str], str] | None = None) -> str:
    """The cells' table; ``deltas``: per scenario, its IR plan's delta now (:func:`plan_deltas`); ``plans``: per
    (scenario, planner), the fingerprint of its plan now (:func:`plan_fingerprints`)."""
    cells = sort_cells(cells, scenarios)
    deltas, plans = deltas or {}, plans or {}
    lines = ["| scenario | simulator | stack | plan | episodes | success | robustness mean (min) | "
             "final speed m/s mean (max) | in final box | mission replans / ep | e error mean / max |",
             "|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|"]
    rows = [row(c, deltas.get(c["scenario"]), plans.get((c["scenario"], c["planner"]))) for c in cells]
    note = (["", "\\* flown with an earlier config of the stack, or before cells recorded theirs (`--stale STACK` "
             "flies it again)"] if any(" * " in r for r in rows) else [])
    if any(" † |" in r for r in rows):
        note += ["", "† flown with an earlier plan of the scenario (another IR delta, or another plan where the cell "
                 "recorded it; the plans in `plans/` are today's): not what today's plans do"]
    return "\n".join(lines + rows + note)


def plan_deltas(out: Path) -> dict[str, float]:
    """Per scenario with a cached IR plan in ``out``/plans/ir/, its delta (m/s)."""
    paths = sorted((out / "plans" / "ir").glob("*.json"))
    return {path.stem: json.loads(path.read_text())["delta_mps"] for path in paths}


def plan_fingerprint(plan: dict) -> str:
    """12 hex digits naming a plan file's content (curves, impacts, copies, funnels, delta), not its solve
    times and stats: what a cell records as the ``plan`` it flew."""
    import hashlib

    text = json.dumps({k: v for k, v in plan.items() if k not in ("solve_time_s", "build_time_s", "stats")},
                      sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:12]


def plan_fingerprints(out: Path) -> dict[tuple[str, str], str]:
    """Per (scenario, planner) with a cached plan in ``out``/plans/, its :func:`plan_fingerprint`."""
    return {(path.stem, planner): plan_fingerprint(json.loads(path.read_text()))
            for planner in PLANNERS for path in sorted((out / "plans" / planner).glob("*.json"))}


def summary(cells: list[dict], scenarios, deltas: dict[str, float], plans: dict[tuple[str, str], str]) -> str:
    """Successes per scenario, stack and plan at 1, 2 and 5 x delta and over the restitution cells, of the cells
    that are current: today's config of the stack (through ``same_flights``), today's delta and plan. A cell
    that is not current is left out ("-"); the full table has it, marked."""
    current: dict[tuple[str, str, str], list[dict]] = {}
    for c in cells:
        if (c["scenario"] in deltas and flown_with_todays_config(c)
                and flown_with_todays_plan(c, deltas[c["scenario"]], plans.get((c["scenario"], c["planner"])))):
            current.setdefault((c["scenario"], c["stack"], c["planner"]), []).append(c)
    lines = ["| scenario | delta (m/s) | stack | plan | 1 x delta | 2 x delta | 5 x delta | e -0.2 .. +0.2 |",
             "|---|---:|---|---|---:|---:|---:|---:|"]
    for name in scenarios:
        for stack in STACKS:
            for planner in PLANNERS:
                group = current.get((name, stack, planner))
                if not group:
                    continue
                cols = []
                for axis, factor in (("noise", 1), ("noise", 2), ("noise", 5), ("e", None)):
                    at = [c for c in group if c["axis"] == axis
                          and (factor is None or abs(c["level"] - factor * c["delta"]) < 1e-12)]
                    eps = [e for c in at for e in c["episodes"]]
                    cols.append(f"{sum(e['success'] for e in eps)} / {len(eps)}" if eps else "-")
                lines.append(f"| {name} | {deltas[name]:.4g} | {stack} | {planner} | " + " | ".join(cols) + " |")
    return "\n".join(lines)


def write_table(out: Path, cells: list[dict]) -> Path:
    """``out``/table.md: the table of every cell (atomically, as the cells), cells of an earlier plan marked;
    and ``out``/summary.md, the successes of the current cells (:func:`summary`)."""
    deltas, plans = plan_deltas(out), plan_fingerprints(out)
    scenarios = all_scenarios(cells)
    write_atomic(out / "summary.md", summary(cells, scenarios, deltas, plans) + "\n")
    return write_atomic(out / "table.md", table(cells, scenarios, deltas, plans) + "\n")


def estimate(scenarios, stacks, seeds: int) -> float:
    """Seconds of one worker, from each scenario's episode length (about 3 ms of controller and simulation
    per control step and robot, measured here on an idle machine)."""
    from impact_env.transport.scenario import load_scenario

    total = 0.0
    for name in scenarios:
        sc = load_scenario(name)
        steps = round(sc.formula.horizon_s / sc.control_period_s)
        n = sum(n for _, _, n in conditions(1.0, seeds)) * len(stacks) * len(PLANNERS)
        total += n * steps * 3e-3 * len(sc.robots)
    return total


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenarios", default=",".join(SHIPPED))
    parser.add_argument("--stacks", default=",".join(DEFAULT_STACKS), help=f"of {', '.join(STACKS)}")
    parser.add_argument("--seeds", type=int, default=50, help="seeds per noisy cell")
    parser.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    parser.add_argument("--out", default=str(RESULTS),
                        help="the cells (cells.jsonl), their table (table.md) and the cached plans (plans/) "
                             "(default: %(default)s)")
    parser.add_argument("--factors", default=None, metavar="K1,K2",
                        help="fly only the noise cells at these multiples of delta (e.g. 1)")
    parser.add_argument("--planners", default=",".join(PLANNERS), help=f"of {', '.join(PLANNERS)}")
    parser.add_argument("--stale", default="", metavar="STACKS",
                        help="comma-separated stacks whose cells flown with another config than the stack's "
                             "current one (or before cells recorded it) are flown again")
    add_restamp_arguments(parser)
    parser.add_argument("--estimate", action="store_true", help="print the estimated time and stop")
    parser.add_argument("--table-only", action="store_true",
                        help="print the table of the cells done (and rewrite table.md); fly nothing")
    args = parser.parse_args()
    scenarios, stacks = args.scenarios.split(","), args.stacks.split(",")
    stale = tuple(s for s in args.stale.split(",") if s)
    if any(s not in STACKS for s in stacks + list(stale)):
        parser.error(f"--stacks and --stale take {', '.join(STACKS)}, got {args.stacks!r} and {args.stale!r}")
    planners = tuple(args.planners.split(","))
    if any(p not in PLANNERS for p in planners):
        parser.error(f"--planners takes {', '.join(PLANNERS)}, got {args.planners!r}")
    try:
        factors = None if args.factors is None else tuple(float(k) for k in args.factors.split(","))
    except ValueError:
        parser.error(f"--factors takes comma-separated numbers (multiples of delta), got {args.factors!r}")
    out = Path(args.out)
    if args.restamp:
        restamped = tuple(st for st in args.restamp.split(",") if st)
        if any(st not in STACKS for st in restamped):
            parser.error(f"--restamp takes {', '.join(STACKS)}, got {args.restamp!r}")
        before = None if args.flown_after is None else CellStore(args.flown_after, key_of)
        print(restamp_report(restamp(cell_store(out), restamped, before), out))
        return
    if args.estimate:
        seconds = estimate(scenarios, stacks, args.seeds)
        print(f"about {seconds / 3600:.1f} h of one worker, {seconds / 3600 / args.workers:.1f} h with "
              f"{args.workers} workers on an idle machine")
        return
    if not args.table_only:
        run(scenarios, stacks, args.seeds, out, args.workers, factors, planners, stale)
    cells = cell_store(out).cells()
    if cells:
        write_table(out, cells)
    print(table(cells, scenarios, plan_deltas(out), plan_fingerprints(out)))


if __name__ == "__main__":
    main()
