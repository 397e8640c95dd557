"""The mission re-plans' weight on each object's own margin (``MissionConfig.conjunct_weight``) in closed loop.

A mission re-plan maximises the task's least robustness rho. An object whose goal does not set rho may then be
sent anywhere within rho of its goal's edge, and the noise of its last impact has that margin to use. With a
weight w > 0 each conjunct on an object adds w times its own robustness to the objective
(``PlannerConfig.conjunct_weight``), so that object keeps the margin it can have. This script flies the full
expert (``ExpertConfig()``, the robustness benchmark's ``all``) with the weights asked for, weight 0 (today's
default) among them as the baseline of the same run, on the robustness benchmark's episodes: the same plan
(``results/robustness/plans/``), env options and seeds (:mod:`benchmarks.robustness`). At weight 0 the
episodes are those of the benchmark's cells, bit for bit. Cells go to ``--out``/cells.jsonl as each finishes
(a rerun resumes) and the table to ``--out``/table.md. From the repository root:

    python -m benchmarks.conjunct_weight [--scenarios one_robot_two_objects,two_objects,...]
        [--weights 0,0.3] [--noise 0.02] [--seeds 50] [--workers 2] [--out results/conjunct_weight]
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from benchmarks import open_engine
from benchmarks.expert_variants import against_baseline, fly_missing
from benchmarks.robustness import RESULTS as ROBUSTNESS
from benchmarks.robustness import _episode, expert_config, plan_for
from impact_env.results_store import CellStore, write_atomic
from impact_env.sweep import EngineConfig

RESULTS = Path(__file__).resolve().parents[1] / "results" / "conjunct_weight"
SCENARIOS = ("one_robot_two_objects", "two_objects", "held_drift", "four_robots", "relay", "obstacle_avoidance",
             "narrow_gap", "timed_visits", "wall_start", "corridor", "ping_pong_stop", "long_throw_trim",
             "throw_and_catch_exp")


def config(weight: float):
    """``ExpertConfig()`` with its mission re-plans at ``weight``."""
    base = expert_config("all")
    return dataclasses.replace(base, mission=dataclasses.replace(base.mission, conjunct_weight=weight))


def fly(job: tuple[str, float, dict, float, int]) -> dict:
    """One episode: (scenario, weight, plan as a dict, noise m/s, seed) -> what it did: the robustness
    benchmark's episode (:func:`benchmarks.robustness._episode`) with the weight's config."""
    name, weight, plan, noise, seed = job
    return _episode((name, f"all, weight {weight:g}", plan, "impact", noise, seed, config(weight)))


def cell_key(cell: dict) -> tuple[str, float, float]:
    return (str(cell["scenario"]), float(cell["weight"]), float(cell["noise_mps"]))


def table(cells: list[dict]) -> str:
    """Success per scenario and weight, and the seeds each weight lost and gained against weight 0."""
    return against_baseline(cells, lambda c: float(c["weight"]), 0.0, lambda w: f"weight {w:g}", "weight 0")


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], allow_abbrev=False)
    parser.add_argument("--scenarios", default=",".join(SCENARIOS))
    parser.add_argument("--weights", default="0,0.3", help="weights in [0, 1], comma-separated (0 is the baseline)")
    parser.add_argument("--noise", default="0.02", help="post-impact noise levels, m/s (comma-separated)")
    parser.add_argument("--seeds", type=int, default=50)
    parser.add_argument("--workers", type=int, default=None, help="local worker processes (default: the CPUs)")
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args(argv)
    try:
        weights = [float(x) for x in args.weights.split(",") if x.strip()]
        levels = [float(x) for x in args.noise.split(",") if x.strip()]
    except ValueError:
        parser.error("--weights and --noise take comma-separated numbers")
    if any(not 0.0 <= w <= 1.0 for w in weights):
        parser.error(f"--weights must lie in [0, 1], got {args.weights!r}")
    if args.seeds < 1:
        parser.error(f"--seeds must be >= 1, got {args.seeds}")
    args.out.mkdir(parents=True, exist_ok=True)
    store = CellStore(args.out / "cells.jsonl", cell_key)
    names = [s for s in args.scenarios.split(",") if s]
    todo = [(n, w, x) for x in levels for n in names for w in weights]
    with open_engine(EngineConfig(workers=args.workers)) as pool:
        for k, (name, weight, noise) in enumerate(todo, 1):
            plan = plan_for(name, ROBUSTNESS)
            cell = fly_missing(store, pool, (name, weight, noise), {"scenario": name, "weight": weight,
                                                                    "noise_mps": noise},
                               fly, [(name, weight, plan, noise, s) for s in range(args.seeds)])
            print(f"[{k}/{len(todo)}] {name} weight {weight:g} at {noise:g} m/s: "
                  f"{sum(e['success'] for e in cell['episodes'])} / {len(cell['episodes'])} ({cell['wall_s']:.0f} s)",
                  flush=True)
    text = table(store.cells())
    write_atomic(args.out / "table.md", text)
    print("\n" + text)


if __name__ == "__main__":
    main()
