"""Expert versus learned on the seven shipped scenarios: the expert and the random controller flown on the pymunk
env on the same seeded episodes as the final evaluation of :mod:`benchmarks.rl_at_scale`'s runs, and one table
joining them with the learned rows (SB3 PPO, MAPPO, IPPO) of ``results/rl_at_scale/cells.jsonl``.

    python -m benchmarks.expert_vs_learned [--episodes 20] [--scenarios corridor,relay]   # fly, then the table
    python -m benchmarks.expert_vs_learned --publish [--docs]   # only the table, from the cells there are

The episodes are the learned evaluation's: :class:`~impact_env.transport.gym_env.TransportEnv` with 5 % thrust
noise and objects starting within 5 cm, seeds 1,000,000, 1,000,001, ... (the learned runs fly 50 or 100 of
them, this script the first ``--episodes``). Success is a final robustness > 0, as there. The expert is the
package's default stack flying the spatially robust plan that the robustness benchmark committed
(``results/robustness/plans/``; planned here where a scenario has none), read once per scenario and copied
into ``--out``/plans/. A cell is one (controller, scenario) in ``--out``/cells.jsonl
(:class:`~impact_env.results_store.CellStore`), written after every episode, so a killed run resumes at the
next episode and a larger ``--episodes`` adds the missing seeds (an episode depends on its seed only).

The table (:mod:`benchmarks.expert_vs_learned_table`) is rebuilt after every cell and by ``--publish``: it
reads whatever learned cells exist, so it can be made again when more land.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

from benchmarks.expert_vs_learned_table import cell_key

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "results" / "expert_vs_learned"
LEARNED = ROOT / "results" / "rl_at_scale" / "cells.jsonl"
COMMITTED_PLANS = ROOT / "results" / "robustness" / "plans"
CONTROLLERS = ("expert", "random")
FIRST_SEED = 1_000_000  # the learned runs' evaluation seeds (baselines.batched.sb3_ppo.EVAL_FIRST_SEED)
NOISE = {"thrust_noise": 0.05, "initial_position_noise_m": 0.05}  # the learned runs' training and evaluation


def plan_file(scenario: str, out: Path) -> tuple[Path, str]:
    """(the plan file the expert flies on ``scenario``, where it came from): ``out``/plans/ if it is there, else
    the robustness benchmark's committed plan copied there, else a new spatially robust plan saved there."""
    from impact_env.results_store import atomic_path, write_atomic

    path = out / "plans" / f"{scenario}.json"
    committed = COMMITTED_PLANS / f"{scenario}.json"
    if path.exists():
        same = committed.exists() and committed.read_bytes() == path.read_bytes()
        return path, f"results/robustness/plans/{scenario}.json" if same else f"planned by {Path(__file__).stem}"
    if committed.exists():
        write_atomic(path, committed.read_bytes())
        return path, f"results/robustness/plans/{scenario}.json"
    from impact_env.transport.scenario import load_scenario
    from planners.offline.spatially_robust import plan_spatially_robust

    plan = plan_spatially_robust(load_scenario(scenario))
    with atomic_path(path) as tmp:  # a kill while saving leaves no half plan
        plan.save(tmp)
    return path, f"planned by {Path(__file__).stem}"


def make_controller(name: str, scenario: str, out: Path) -> tuple[Any, dict]:
    """The controller ``name`` (:data:`CONTROLLERS`) for ``scenario`` and what the cell records about it."""
    if name == "random":
        from impact_env.controllers import RandomController

        return RandomController(), {}
    if name != "expert":
        raise ValueError(f"unknown controller {name!r}; choose from {', '.join(CONTROLLERS)}")
    import dataclasses
    import hashlib

    from impact_env.transport.scenario import load_scenario
    from planners.expert import Expert
    from planners.plan import Plan

    path, source = plan_file(scenario, out)
    plan = Plan.load(path)
    expert = Expert(load_scenario(scenario), plan=plan)
    config = json.dumps(dataclasses.asdict(expert.config), sort_keys=True, default=repr)
    return expert, {"plan": {"source": source, "robustness": float(plan.robustness)},
                    "expert_config": hashlib.sha256(config.encode()).hexdigest()[:12]}


def fly_episode(env: Any, controller: Any, seed: int) -> dict:
    """One seeded episode to the task's horizon: its final robustness (m), success (robustness > 0, as the learned
    evaluation counts it), fuel (N s), robot-object impacts and wall clock (s)."""
    from impact_env.rollout import robot_object_impacts, run_episode

    result = run_episode(env, controller, seed=seed)
    return {"seed": seed, "robustness": float(result.robustness), "success": bool(result.robustness > 0.0),
            "fuel_Ns": float(result.fuel_Ns), "impacts": len(robot_object_impacts(env.unwrapped.scenario,
                                                                                 result.impacts)),
            "steps": int(result.steps), "wall_s": round(float(result.wall_time_s), 3)}


def fly_cell(store: Any, controller: str, scenario: str, episodes: int, out: Path) -> dict:
    """Fly the episodes of one cell that are not in ``store`` yet, putting the cell after each; returns it."""
    from impact_env.transport.gym_env import TransportEnv

    cell = store.get((controller, scenario))
    if cell is not None and (cell["first_seed"] != FIRST_SEED or cell["env_options"] != NOISE):
        raise SystemExit(f"{store.path}: the cell {controller} / {scenario} was flown with other episodes "
                         f"(first seed {cell['first_seed']}, {cell['env_options']}); give another --out")
    done = [] if cell is None else cell["episodes"]
    if len(done) >= episodes:
        return cell
    policy, about = make_controller(controller, scenario, out)
    env = TransportEnv(scenario, **NOISE)
    wall = 0.0 if cell is None else float(cell["wall_s"])
    for i in range(len(done), episodes):
        start = time.perf_counter()
        done = done + [fly_episode(env, policy, FIRST_SEED + i)]
        wall += time.perf_counter() - start
        cell = {"controller": controller, "scenario": scenario, "world": "pymunk", "first_seed": FIRST_SEED,
                "env_options": NOISE, "episodes_requested": max(episodes, len(done)), **about,
                "episodes": done, "wall_s": round(wall, 2)}
        store.put(cell)
    env.close()
    return cell


def run(scenarios: list[str], controllers: list[str], episodes: int, out: Path, learned: Path,
        reps: int) -> None:
    """Fly every (controller, scenario) cell that is not done, rebuilding the table after each."""
    from benchmarks.expert_vs_learned_table import write_summary
    from impact_env.results_store import CellStore

    store = CellStore(out / "cells.jsonl", cell_key)
    for scenario in scenarios:
        for controller in controllers:
            start = time.perf_counter()
            cell = fly_cell(store, controller, scenario, episodes, out)
            eps = cell["episodes"]
            print(f"{scenario:20s} {controller:7s} {sum(e['success'] for e in eps)}/{len(eps)} succeed, robustness "
                  f"mean {sum(e['robustness'] for e in eps) / len(eps):+.3f} m ({time.perf_counter() - start:.0f} s)",
                  flush=True)
            write_summary(out, learned, reps)


def main(argv: list[str] | None = None) -> None:
    from benchmarks.rl_at_scale import SCENARIOS

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenarios", default=",".join(SCENARIOS), help="comma-separated (default: the seven)")
    parser.add_argument("--controllers", default=",".join(CONTROLLERS), help="expert, random or both")
    parser.add_argument("--episodes", type=int, default=20, help="seeded episodes per cell (the learned runs "
                        "were evaluated on 50-100)")
    parser.add_argument("--out", type=Path, default=RESULTS, help="cells.jsonl, plans/, summary.md, summary.json")
    parser.add_argument("--learned", type=Path, default=LEARNED, help="the learned runs' cells (rl_at_scale's)")
    parser.add_argument("--reps", type=int, default=2000, help="bootstrap resamples of the intervals")
    parser.add_argument("--publish", action="store_true", help="fly nothing: only rebuild the table from the cells")
    parser.add_argument("--docs", action="store_true", help="also put the table into docs/baselines.md")
    args = parser.parse_args(argv)
    scenarios = [s for s in args.scenarios.split(",") if s]
    controllers = [c for c in args.controllers.split(",") if c]
    unknown = [s for s in scenarios if s not in SCENARIOS] + [c for c in controllers if c not in CONTROLLERS]
    if unknown:
        parser.error(f"unknown {', '.join(unknown)}: scenarios are {', '.join(SCENARIOS)}; controllers "
                     f"{', '.join(CONTROLLERS)}")
    if args.episodes < 1 or args.reps < 1:
        parser.error("--episodes and --reps must be >= 1")
    try:
        import rliable  # noqa: F401  (the learned rows' intervals)
    except ImportError:
        raise SystemExit("expert_vs_learned: the table needs rliable: pip install -e '.[rl-analysis]'") from None
    from benchmarks.expert_vs_learned_table import write_docs, write_summary
    from impact_env.results_store import check_output_folder

    check_output_folder(args.out, "--out")
    if not args.publish:
        run(scenarios, controllers, args.episodes, args.out, args.learned, args.reps)
    text = write_summary(args.out, args.learned, args.reps)
    if args.docs:
        write_docs(args.out, ROOT / "docs" / "baselines.md")
    print(text)


if __name__ == "__main__":
    main()
