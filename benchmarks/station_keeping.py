"""Station keeping in closed loop: the full expert on tasks with a held goal (``G[a, b] in(O, region)``) under
post-impact velocity noise, with the trim triggered at each of several margins, and with station keeping off.

A trim is itself an impact, and under post-impact noise it adds a velocity error of its own, which the object
then carries to the end of the window. So a trim pays only where the drift would really leave the goal: the
margin (``StationKeepingConfig.margin_m``) decides how close to the edge a predicted drift may come before a
trim is planned. This script measures that trade. Each cell (scenario, variant, noise) flies the same seeded
episodes (``TransportEnv(impact_velocity_noise_mps=noise)``, seeds 0..N-1) with ``ExpertConfig()`` and its
mission's station keeping replaced by the variant: ``off``, or a margin in metres. The offline plan is the
spatially robust planner's default, cached in ``--out``/plans/. Cells go to ``--out``/cells.jsonl as each
finishes (an interrupted run resumes), and the table to ``--out``/table.md. From the repository root:

    python -m benchmarks.station_keeping [--scenarios held_drift,ping_pong_stop,two_objects,narrow_gap]
        [--variants 0,0.05,off] [--noise 0.02] [--seeds 20] [--out results/station_keeping]
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import time
from pathlib import Path

from benchmarks.robustness import plan_for
from impact_env.results_store import CellStore, write_atomic

RESULTS = Path(__file__).resolve().parents[1] / "results" / "station_keeping"
SCENARIOS = ("held_drift", "ping_pong_stop", "two_objects", "narrow_gap")


def cell_key(cell: dict) -> tuple[str, str, float]:
    return (str(cell["scenario"]), str(cell["variant"]), float(cell["noise_mps"]))


def expert_config(variant: str):
    """``ExpertConfig()`` with its station keeping ``off`` or at margin ``variant`` (m)."""
    from planners.expert import ExpertConfig
    from planners.online.station_keeping import StationKeepingConfig

    config = ExpertConfig()
    keeping = None if variant == "off" else StationKeepingConfig(margin_m=float(variant))
    return dataclasses.replace(config, mission=dataclasses.replace(config.mission, station_keeping=keeping))


def fly_cell(scenario_name: str, variant: str, noise: float, seeds: int, out: Path) -> dict:
    """One cell: ``seeds`` episodes of the expert with ``variant``'s station keeping."""
    from impact_env.rollout import run_episode
    from impact_env.transport.gym_env import TransportEnv
    from impact_env.transport.scenario import load_scenario
    from planners.expert import Expert
    from planners.plan import Plan

    scenario = load_scenario(scenario_name)
    plan = Plan.from_dict(plan_for(scenario_name, out))
    config = expert_config(variant)
    episodes, start = [], time.perf_counter()
    for seed in range(seeds):
        expert = Expert(scenario, plan=plan, config=config)
        result = run_episode(TransportEnv(scenario, impact_velocity_noise_mps=noise), expert, seed=seed)
        mission = expert.report().get("mission") or {}
        episodes.append({"seed": seed, "success": bool(result.success), "robustness": float(result.robustness),
                         "trims": int(mission.get("trims", 0))})
    return {"scenario": scenario_name, "variant": variant, "noise_mps": noise, "seeds": seeds,
            "successes": sum(e["success"] for e in episodes), "episodes": episodes,
            "wall_s": round(time.perf_counter() - start, 1), "load_average_1min": round(os.getloadavg()[0], 2)}


def table(cells: list[dict]) -> str:
    """Success per scenario (rows) and variant (columns), one table per noise level, the failing seeds below."""
    lines = []
    for noise in sorted({c["noise_mps"] for c in cells}):
        at = [c for c in cells if c["noise_mps"] == noise]
        variants = sorted({c["variant"] for c in at}, key=lambda v: (v == "off", float(v) if v != "off" else 0.0))
        names = list(dict.fromkeys(c["scenario"] for c in at))
        by = {(c["scenario"], c["variant"]): c for c in at}
        lines += [f"Post-impact noise {noise:g} m/s per axis; success / episodes (trims accepted)", "",
                  "| scenario | " + " | ".join("off" if v == "off" else f"margin {v} m" for v in variants) + " |",
                  "|---|" + "---:|" * len(variants)]
        total = {v: [0, 0] for v in variants}
        for name in names:
            row = []
            for v in variants:
                c = by.get((name, v))
                if c is None:
                    row.append("-")
                    continue
                trims = sum(e["trims"] for e in c["episodes"])
                row.append(f"{c['successes']} / {c['seeds']} ({trims})")
                total[v][0] += c["successes"]
                total[v][1] += c["seeds"]
            lines.append(f"| {name} | " + " | ".join(row) + " |")
        lines.append("| **all** | " + " | ".join(f"**{s} / {n}**" for s, n in total.values()) + " |")
        lines += ["", "Failing seeds: " + "; ".join(
            f"{c['scenario']} {c['variant']}: {','.join(str(e['seed']) for e in c['episodes'] if not e['success'])}"
            for c in at if c["successes"] < c["seeds"]) or "none", ""]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], allow_abbrev=False)
    parser.add_argument("--scenarios", default=",".join(SCENARIOS))
    parser.add_argument("--variants", default="0,0.05,off", help="margins in m, or off (comma-separated)")
    parser.add_argument("--noise", default="0.02", help="post-impact noise levels, m/s (comma-separated)")
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    variants = [v.strip() for v in args.variants.split(",") if v.strip()]
    for v in variants:
        if v != "off":
            try:
                if float(v) < 0:
                    raise ValueError
            except ValueError:
                parser.error(f"--variants: {v!r} is neither a margin >= 0 (m) nor off")
    try:
        levels = [float(x) for x in args.noise.split(",") if x.strip()]
    except ValueError:
        parser.error(f"--noise must be comma-separated numbers, got {args.noise!r}")
    if args.seeds < 1:
        parser.error(f"--seeds must be >= 1, got {args.seeds}")
    args.out.mkdir(parents=True, exist_ok=True)
    store = CellStore(args.out / "cells.jsonl", cell_key)
    names = [s for s in args.scenarios.split(",") if s]
    todo = [(n, v, x) for x in levels for n in names for v in variants]
    for k, (name, variant, noise) in enumerate(todo, 1):
        cell = store.get((name, variant, noise))
        if cell is None or cell["seeds"] < args.seeds:
            cell = fly_cell(name, variant, noise, args.seeds, args.out)
            store.put(cell)
        print(f"[{k}/{len(todo)}] {name} {variant} {noise:g} m/s: {cell['successes']} / {cell['seeds']} "
              f"({cell['wall_s']:.0f} s)", flush=True)
    text = table(store.cells())
    write_atomic(args.out / "table.md", text)
    print("\n" + text)


if __name__ == "__main__":
    main()
