"""Re-fly every episode of a robustness-benchmark cell in this process and compare with the cell, bit for bit.

    python -m benchmarks.robustness_reproduce SCENARIO STACK AXIS LEVEL [--order fresh|forward|reversed]
        [--allow-side-switches] [--results results/robustness]
    python -m benchmarks.robustness_reproduce two_objects +mission combined 0 --allow-side-switches

The cell's episodes were flown by :mod:`benchmarks.robustness` workers, each keeping one expert per
scenario and stack and resetting it between the seeds it was given. ``--order`` flies them here under another
history: ``fresh`` (default) builds a new expert for every seed; ``forward`` and ``reversed`` fly all seeds
with one expert, reset between episodes, in the cell's order or backwards. Same seed, same episode: every
row must say ``same``, whatever the order (the robustness is compared exactly, not rounded).
``--allow-side-switches`` flies mission re-plans with a side switch, as the cells flown before
``MissionConfig.allow_side_switches`` existed were (:mod:`benchmarks.robustness_episode`). The cell and its
plan are read from ``--results`` (the robustness benchmark's ``--out``: cells.jsonl and plans/).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from benchmarks.robustness import RESULTS, add_cell_arguments, env_options, expert_config, load_cell, plan_path


def reproduce(scenario_name: str, stack: str, axis: str, level: float, order: str = "fresh",
              allow_side_switches: bool = False, results: Path = RESULTS) -> list[tuple[int, float, float]]:
    """(seed, the cell's robustness, the re-flown robustness) for every episode of the cell."""
    from impact_env.rollout import run_episode
    from impact_env.transport.gym_env import TransportEnv
    from impact_env.transport.scenario import load_scenario
    from planners.expert import Expert
    from planners.plan import Plan

    cell = load_cell(results, scenario_name, stack, axis, level)
    scenario = load_scenario(scenario_name)
    plan = Plan.load(plan_path(results, scenario.name))
    config = expert_config(stack, allow_side_switches)
    episodes = cell["episodes"][::-1] if order == "reversed" else cell["episodes"]
    kept = Expert(scenario, plan=plan, config=config) if order != "fresh" else None
    rows = []
    for ep in episodes:
        expert = kept or Expert(scenario, plan=plan, config=config)
        env = TransportEnv(scenario, **env_options(scenario, axis, level, ep["seed"]))
        rows.append((ep["seed"], ep["robustness"], float(run_episode(env, expert, seed=ep["seed"]).robustness)))
    return sorted(rows)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_cell_arguments(ap)
    ap.add_argument("--order", choices=("fresh", "forward", "reversed"), default="fresh")
    ap.add_argument("--results", type=Path, default=RESULTS,
                    help="the robustness benchmark's --out (cells.jsonl, plans/) (default: %(default)s)")
    args = ap.parse_args(argv)
    stack = args.stack
    rows = reproduce(args.scenario, stack, args.axis, args.level, args.order, args.allow_side_switches,
                     args.results)
    print(f"{args.scenario} / {stack} / {args.axis} {args.level:g}, order {args.order}\n")
    print("| seed | cell robustness | re-flown | |\n|---:|---:|---:|---|")
    for seed, cell, again in rows:
        verdict = "same" if again == cell else f"DIFFERS by {again - cell:+.2g}"
        print(f"| {seed} | {cell:+.6f} | {again:+.6f} | {verdict} |")
    same = sum(again == cell for _, cell, again in rows)
    print(f"\n{same} of {len(rows)} episodes bit-identical to the cell")
    return 0 if same == len(rows) else 1


if __name__ == "__main__":
    sys.exit(main())
