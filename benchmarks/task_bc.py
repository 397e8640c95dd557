"""Behaviour cloning on generated tasks, evaluated on held-out tasks against the expert, in the same run.

For each family, from the kept tasks of ``results/task_generator/<family>/`` (``python -m
benchmarks.task_generator``):

1. the datasets (:mod:`baselines.task_dataset`): ``--episodes-per-task`` expert episodes per task under 5 %
   thrust noise and 5 cm start noise, a share ``--heldout`` of the tasks held out by split seed 0;
2. one goal-conditioned BC policy per training seed (:mod:`baselines.task_bc`, ``--seeds``);
3. every policy and the expert flown on every held-out task for ``--eval-episodes`` env seeds (from 1000,
   seeds no dataset episode used), under the same noise.

Reported per family and controller: success rate over (task, env seed) episodes with a 95 % bootstrap
interval (resampling tasks, then episodes; for BC pooled over its training seeds, with each seed's own rate),
mean final robustness, median ms per step of the controller, and for BC the training budget: dataset steps
(environment steps the expert flew; BC takes no new ones), epochs and wall clock. Cells (one per family,
controller and training seed) go to ``results/task_bc/cells.jsonl``, the datasets and runs to
``datasets/task_bc`` and ``runs/task_bc``; a rerun skips the cells there. Usage:

    python -m benchmarks.task_bc [--families gaps] [--seeds 0,1,2] [--eval-episodes 5] [--episodes-per-task 3]
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path
from typing import Any

import numpy as np

OUT = Path("results/task_bc")
TASKS = Path("results/task_generator")
DATASETS = Path("datasets/task_bc")
RUNS = Path("runs/task_bc")
NOISE = {"thrust_noise": 0.05, "initial_position_noise_m": 0.05}
EVAL_SEED0 = 1000


def bootstrap_ci(by_task: dict[str, list[float]], n: int = 2000, seed: int = 0) -> tuple[float, float]:
    """95 % percentile interval of the mean over tasks, resampling tasks and then each task's episodes."""
    rng = np.random.default_rng(seed)
    tasks = list(by_task)
    if not tasks:
        return float("nan"), float("nan")
    means = []
    for _ in range(n):
        picked = rng.choice(len(tasks), size=len(tasks))
        vals = []
        for t in picked:
            eps = by_task[tasks[t]]
            vals.extend(rng.choice(eps, size=len(eps)))
        means.append(float(np.mean(vals)))
    return float(np.percentile(means, 2.5)), float(np.percentile(means, 97.5))


def success_cell(episodes: list[dict]) -> tuple[float, str]:
    """(success rate, ``"95 (82-100) of 40"``): the episodes' success % with its :func:`bootstrap_ci` interval
    over their tasks, as the held-out tables print it."""
    by_task: dict[str, list[float]] = {}
    for e in episodes:
        by_task.setdefault(e["task"], []).append(float(e["success"]))
    lo, hi = bootstrap_ci(by_task)
    rate = float(np.mean([e["success"] for e in episodes]))
    return rate, f"{100 * rate:.0f} ({100 * lo:.0f}-{100 * hi:.0f}) of {len(episodes)}"


def fly_episode(scenario, controller, seed: int, family: str | None) -> dict:
    """One held-out episode under :data:`NOISE`: the controller on the scenario's env, seen through ``family``'s
    padded layout when given (a goal-conditioned policy), else the env's own observation (the expert)."""
    from impact_env.rollout import run_episode
    from impact_env.transport.generate import FAMILY_LIMITS
    from impact_env.transport.gym_env import TransportEnv
    from impact_env.transport.task_observation import TaskConditioned

    env: Any = TransportEnv(scenario, **NOISE)
    if family is not None:
        env = TaskConditioned(env, FAMILY_LIMITS[family])
    result = run_episode(env, controller, seed=seed)
    env.close()
    return {"task": scenario.name, "seed": seed, "success": bool(result.success),
            "robustness_m": float(result.robustness), "ms_per_step": float(np.median(result.controller_ms))}


def run_family(family: str, seeds: list[int], eval_episodes: int, episodes_per_task: int, heldout: float,
               epochs: int) -> None:
    from baselines.task_bc import TaskBCConfig, TaskBCPolicy, train_task_bc
    from baselines.task_dataset import DatasetConfig, build_dataset, split_tasks
    from impact_env.results_store import CellStore
    from planners.expert import Expert
    from planners.task_filter import load_kept

    store = CellStore(OUT / "cells.jsonl", key=lambda c: (c["family"], c["controller"], c["train_seed"]))
    kept = load_kept(TASKS / family)
    names = [t[0].name for t in kept]
    train_names, held_names = split_tasks(names, heldout, 0)
    held = [t for t in kept if t[0].name in held_names]
    datasets = DATASETS / family
    split_file = datasets / "impact_env" / f"generated_{family}" / "split.json"
    stale = not split_file.is_file() or sorted(json.loads(split_file.read_text())["train"]) != sorted(train_names)
    if stale:
        start = time.perf_counter()
        build_dataset(family, TASKS / family, DatasetConfig(episodes_per_task=episodes_per_task, heldout_share=heldout,
                                                            env_options=NOISE), out=datasets)
        print(f"{family}: datasets built in {time.perf_counter() - start:.0f} s", flush=True)
    if (family, "expert", None) not in store:
        episodes = []
        for scenario, plan, _ in held:
            expert = Expert(scenario, plan=plan)
            episodes += [fly_episode(scenario, expert, EVAL_SEED0 + k, None) for k in range(eval_episodes)]
        store.put({"family": family, "controller": "expert", "train_seed": None, "train_tasks": len(train_names),
                   "heldout_tasks": held_names, "episodes": episodes})
    for seed in seeds:
        if (family, "bc", seed) in store:
            continue
        run = train_task_bc(TaskBCConfig(family, datasets_dir=str(datasets), seed=seed, epochs=epochs,
                                         out=str(RUNS / f"{family}_s{seed}")))
        train = json.loads((run / "train.json").read_text())
        policy = TaskBCPolicy.load(run)
        episodes = [fly_episode(sc, policy, EVAL_SEED0 + k, family) for sc, _, _ in held
                    for k in range(eval_episodes)]
        store.put({"family": family, "controller": "bc", "train_seed": seed, "train_tasks": len(train_names),
                   "heldout_tasks": held_names, "dataset_steps": train["steps"], "dataset_episodes": train["episodes"],
                   "epochs": epochs, "final_loss": train["final_loss"], "train_wall_s": train["wall_s"],
                   "episodes": episodes})
        ok = np.mean([e["success"] for e in episodes])
        print(f"{family}: BC seed {seed}: held-out success {100 * ok:.0f} % ({len(episodes)} episodes)", flush=True)


def table() -> str:
    from impact_env.results_store import CellStore

    store = CellStore(OUT / "cells.jsonl", key=lambda c: (c["family"], c["controller"], c["train_seed"]))
    rows = ["| family | controller | train / held-out tasks | held-out success % (95 % CI) | per training seed % | "
            "robustness m (mean) | ms/step (median) | dataset steps | epochs | train wall s |", "|" + "---|" * 10]
    families = list(dict.fromkeys(c["family"] for c in store))
    for family in families:
        for controller in ("expert", "bc"):
            cells = [c for c in store if c["family"] == family and c["controller"] == controller]
            if not cells:
                continue
            eps = [e for c in cells for e in c["episodes"]]
            _, success = success_cell(eps)
            per_seed = ", ".join(f"{100 * np.mean([e['success'] for e in c['episodes']]):.0f}" for c in cells)
            bc = controller == "bc"
            wall = f"{statistics.fmean(c['train_wall_s'] for c in cells):.0f}" if bc else "-"
            rows.append(
                f"| {family} | {controller}{f' ({len(cells)} seeds)' if bc else ''} | {cells[0]['train_tasks']} / "
                f"{len(cells[0]['heldout_tasks'])} | {success} | "
                f"{per_seed if bc else '-'} | {statistics.fmean(e['robustness_m'] for e in eps):+.3f} | "
                f"{statistics.median(e['ms_per_step'] for e in eps):.2f} | "
                f"{cells[0]['dataset_steps'] if bc else '-'} | {cells[0]['epochs'] if bc else '-'} | "
                f"{wall} |")
    return "\n".join(rows) + "\n"


def main(argv: list[str] | None = None) -> int:
    from impact_env.transport.generate import FAMILIES

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--families", default=",".join(FAMILIES))
    parser.add_argument("--seeds", default="0,1,2", help="BC training seeds")
    parser.add_argument("--eval-episodes", type=int, default=5, help="env seeds per held-out task")
    parser.add_argument("--episodes-per-task", type=int, default=3, help="expert episodes per task in the datasets")
    parser.add_argument("--heldout", type=float, default=0.25, help="share of tasks held out")
    parser.add_argument("--epochs", type=int, default=40)
    parser.add_argument("--table-only", action="store_true")
    args = parser.parse_args(argv)
    if not args.table_only:
        for family in args.families.split(","):
            run_family(family, [int(s) for s in args.seeds.split(",")], args.eval_episodes, args.episodes_per_task,
                       args.heldout, args.epochs)
    from impact_env.results_store import write_atomic

    text = table()
    write_atomic(OUT / "table.md", text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
