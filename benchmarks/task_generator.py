"""The task generator's benchmark: generated tasks drawn, planned (kept if rho > 0) and flown by the expert.

For each family and seed, the task is drawn (:mod:`impact_env.transport.generate`), planned by the spatially
robust MILP within the filter's node budget (:mod:`planners.task_filter`: kept if it finds a plan with
rho > 0), and every kept task is flown once by the expert (the full stack, nominal conditions, env seed 0).
The baseline, measured in the same run with the same budget: the shipped scenario of each family
(``throw_and_catch_exp``, ``obstacle_avoidance``, ``narrow_gap``, ``timed_visits``), planned and flown alike.

Per family it reports the keep rate (with a Wilson 95 % interval), why tasks were dropped, planning times
(median and 90th percentile of the planner's wall time, with the load average at the end), and for the kept
ones the expert's success rate (Wilson 95 %), mean final robustness against the plan's rho, and the expert's
median ms per step. Seeds run family after family in turns (seed 0 of each family, then seed 1, ...), so an
interrupted run has every family covered. Output, resumable (a rerun skips what is there):

    results/task_generator/<family>/verdicts.jsonl   the filter's verdict of every seed
    results/task_generator/<family>/<name>.toml, <name>.plan.json   every kept task and its plan
    results/task_generator/<family>/flights.jsonl    the expert's episode on every kept task
    results/task_generator/<family>/shipped.jsonl    the baseline: the family's shipped scenario
    results/task_generator/table.md                  the table printed at the end

One process per family set may run at once (each family's files have one writer). Usage:

    python -m benchmarks.task_generator [--families gaps,timed_visits] [--tasks 25] [--node-limit 2000]
    python -m benchmarks.task_generator --table-only
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
from dataclasses import asdict
from pathlib import Path

OUT = Path("results/task_generator")
SHIPPED = {"throw_and_catch": "throw_and_catch_exp", "obstacle_avoidance": "obstacle_avoidance",
           "gaps": "narrow_gap", "timed_visits": "timed_visits"}


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """Wilson score interval of a proportion k / n (95 % by default); (nan, nan) for n = 0."""
    if n == 0:
        return math.nan, math.nan
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return max(0.0, centre - half), min(1.0, centre + half)


def fly(scenario, plan, seed: int = 0, config=None, env_options: dict | None = None) -> dict:
    """One expert episode on ``scenario`` flying ``plan``: success, robustness, steps, ms per step.
    ``config``: the expert's (None: its default); ``env_options``: the env's keywords (noise, restitution)."""
    import numpy as np

    from impact_env.rollout import robot_object_impacts, run_episode
    from impact_env.transport.gym_env import TransportEnv
    from planners.expert import Expert

    env = TransportEnv(scenario, **(env_options or {}))
    expert = Expert(scenario, plan=plan, config=config)
    result = run_episode(env, expert, seed=seed)
    env.close()
    return {"seed": seed, "success": bool(result.success), "robustness_m": float(result.robustness),
            "steps": result.steps, "impacts": len(robot_object_impacts(scenario, result.impacts)),
            "fuel_Ns": float(result.fuel_Ns), "ms_per_step": float(np.median(result.controller_ms)),
            "replans": int(expert.replans), "wall_s": float(result.wall_time_s)}


def _folder(family: str) -> Path:
    return OUT / family


def run_shipped(family: str, config) -> None:
    """The baseline cell of ``family``: its shipped scenario planned with the same budget and flown."""
    from impact_env.results_store import CellStore
    from impact_env.transport.scenario import load_scenario
    from planners.task_filter import filter_scenario

    store = CellStore(_folder(family) / "shipped.jsonl", key=lambda c: c["name"])
    name = SHIPPED[family]
    if name in store:
        return
    sc = load_scenario(name)
    verdict, plan = filter_scenario(sc, config, family=family)
    cell = {**asdict(verdict), "flight": fly(sc, plan) if plan is not None else None}
    store.put(cell)
    print(f"  shipped {name}: {verdict.reason} rho {verdict.robustness_m} ({verdict.plan_s:.1f} s); "
          f"flight {cell['flight']}", flush=True)


def run_seed(family: str, seed: int, config) -> None:
    from impact_env.results_store import CellStore
    from impact_env.transport.generate import task_name
    from impact_env.transport.scenario_toml import scenario_from_toml
    from planners.plan import Plan
    from planners.task_filter import filter_tasks

    folder = _folder(family)
    (verdict,) = filter_tasks(family, [seed], folder, config, progress=True)
    if not verdict.kept:
        return
    flights = CellStore(folder / "flights.jsonl", key=lambda c: c["name"])
    name = task_name(family, seed)
    if name in flights:
        return
    scenario = scenario_from_toml((folder / f"{name}.toml").read_text(encoding="utf-8"), source=name)
    flight = fly(scenario, Plan.load(folder / f"{name}.plan.json"))
    flights.put({"name": name, "family": family, "seed": seed, **flight})
    print(f"    expert: {'success' if flight['success'] else 'failure'}, robustness {flight['robustness_m']:+.3f} m, "
          f"{flight['ms_per_step']:.1f} ms/step", flush=True)


def _pct(x: float) -> str:
    return "-" if math.isnan(x) else f"{100 * x:.0f}"


def table(families: list[str]) -> str:
    from impact_env.results_store import CellStore

    rows = ["| family | tasks | kept | keep rate % (95 % CI) | dropped (reason: n) | cut by the time limit | "
            "plan s median / p90 | expert success % (95 % CI) | expert robustness m (mean) | plan rho m (mean) | "
            "expert ms/step (median) |", "|" + "---|" * 11]
    for family in families:
        shipped = CellStore(_folder(family) / "shipped.jsonl", key=lambda c: c["name"])
        verdicts = CellStore(_folder(family) / "verdicts.jsonl", key=lambda c: c["name"]).cells()
        flights = CellStore(_folder(family) / "flights.jsonl", key=lambda c: c["name"]).cells()
        if not verdicts:
            continue
        n, kept = len(verdicts), sum(v["kept"] for v in verdicts)
        lo, hi = wilson(kept, n)
        reasons: dict[str, int] = {}
        for v in verdicts:
            if not v["kept"]:
                reasons[v["reason"]] = reasons.get(v["reason"], 0) + 1
        times = sorted(v["plan_s"] for v in verdicts)
        p90 = times[min(len(times) - 1, int(math.ceil(0.9 * len(times))) - 1)]
        ok = sum(f["success"] for f in flights)
        slo, shi = wilson(ok, len(flights))
        rho = [v["robustness_m"] for v in verdicts if v["kept"]]
        rows.append(f"| {family} | {n} | {kept} | {_pct(kept / n)} ({_pct(lo)}-{_pct(hi)}) | "
                    f"{', '.join(f'{k}: {c}' for k, c in sorted(reasons.items())) or '-'} | "
                    f"{sum(v['budget'] == 'time' for v in verdicts)} | "
                    f"{statistics.median(times):.1f} / {p90:.1f} | "
                    f"{_pct(ok / len(flights)) if flights else '-'} ({_pct(slo)}-{_pct(shi)}) of {len(flights)} | "
                    f"{statistics.fmean(f['robustness_m'] for f in flights) if flights else math.nan:+.3f} | "
                    f"{statistics.fmean(rho) if rho else math.nan:.3f} | "
                    f"{statistics.median(f['ms_per_step'] for f in flights) if flights else math.nan:.1f} |")
        base = shipped.get(SHIPPED[family])
        if base is not None:
            f = base["flight"] or {}
            rows.append(f"| baseline: shipped {base['name']} | 1 | {int(base['kept'])} | - | "
                        f"{'-' if base['kept'] else base['reason']} | {int(base['budget'] == 'time')} | "
                        f"{base['plan_s']:.1f} | "
                        f"{_pct(float(f['success'])) if f else '-'} | "
                        f"{f.get('robustness_m', math.nan):+.3f} | {base['robustness_m'] or math.nan:.3f} | "
                        f"{f.get('ms_per_step', math.nan):.1f} |")
    load = os.getloadavg()
    return "\n".join(rows) + (f"\n\nload average at the end (1, 5, 15 min): {load[0]:.1f}, {load[1]:.1f}, "
                              f"{load[2]:.1f}\n")


def main(argv: list[str] | None = None) -> int:
    global OUT
    from impact_env.transport.generate import FAMILIES

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--families", default=",".join(FAMILIES), help="comma-separated families (default: all)")
    parser.add_argument("--tasks", type=int, default=25, help="seeds 0..N-1 of each family (default 25)")
    parser.add_argument("--node-limit", type=int, default=None, help="the filter's node budget (default: its own)")
    parser.add_argument("--out", default="results/task_generator", help="the results folder (default "
                        "results/task_generator)")
    parser.add_argument("--table-only", action="store_true", help="print the table of the cells there and stop")
    args = parser.parse_args(argv)
    OUT = Path(args.out)
    families = [f for f in args.families.split(",") if f]
    unknown = sorted(set(families) - set(FAMILIES))
    if unknown:
        parser.error(f"unknown families {unknown}; families: {', '.join(FAMILIES)}")
    if not args.table_only:
        from planners.task_filter import FilterConfig

        config = FilterConfig() if args.node_limit is None else FilterConfig(node_limit=args.node_limit)
        for family in families:
            run_shipped(family, config)
        for seed in range(args.tasks):
            for family in families:
                run_seed(family, seed, config)
    text = table(list(FAMILIES))
    from impact_env.results_store import write_atomic

    write_atomic(OUT / "table.md", text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
