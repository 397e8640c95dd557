"""Behaviour cloning on generated tasks, evaluated on held-out tasks against the expert, in the same run.

For each family, from the kept tasks of ``<--tasks>/<family>/`` (default ``results/task_generator``, written by
``python -m benchmarks.task_generator``):

1. the training dataset (:mod:`baselines.task_dataset`): ``--episodes-per-task`` expert episodes per training
   task under 5 % thrust noise and 5 cm start noise, a share ``--heldout`` of the tasks held out by split seed 0
   (a function of each task's name: the held-out tasks are never in the dataset);
2. one goal-conditioned BC policy per training seed (:mod:`baselines.task_bc`, ``--seeds``; ``--epochs``,
   ``--hidden``, ``--observation-noise``), named ``--label`` in the table (so settings compare on one split);
3. every policy and the expert flown on every held-out task for ``--eval-episodes`` env seeds (from 1000,
   seeds no dataset episode used), under the same noise.

Reported per family, task folder and controller: success rate over (task, env seed) episodes with a 95 %
bootstrap interval (resampling tasks, then episodes; for BC pooled over its training seeds, with each seed's own
rate), BC's success as a share of the expert's on the same held-out tasks (paired bootstrap interval; the issue
asks for 0.8), mean final robustness, median ms per step of the controller, and for BC its action error (mean
squared, per action number) on the clean training steps and on the held-out expert's own steps (an open-loop
error on unseen tasks, measured without flying BC; the expert's row gives that of the zero action, the error of
a policy that learned nothing) and the training budget: dataset steps (environment steps
the expert flew; BC takes no new ones), epochs and wall clock. Cells (one per
family, task folder, controller and training seed) go to ``results/task_bc/cells.jsonl``, the datasets and runs
to ``datasets/task_bc`` and ``runs/task_bc``; a rerun skips the cells there. Usage:

    python -m benchmarks.task_bc [--families gaps] [--tasks DIR] [--seeds 0,1,2] [--eval-episodes 5]
        [--episodes-per-task 3] [--label bc] [--epochs 40] [--hidden 256,256] [--observation-noise 0.05]
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path
from typing import Any

import numpy as np

from impact_env.errors import ImpactEnvError

OUT = Path("results/task_bc")
TASKS = Path("results/task_generator")
DATASETS = Path("datasets/task_bc")
RUNS = Path("runs/task_bc")
NOISE = {"thrust_noise": 0.05, "initial_position_noise_m": 0.05}
EVAL_SEED0 = 1000


def cell_key(cell: dict) -> tuple:
    """A cell's identity: family, task folder (cells older than ``--tasks`` used the default), controller (the
    expert or a BC label) and training seed."""
    return cell["family"], cell.get("tasks_dir", str(TASKS)), cell["controller"], cell["train_seed"]


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


def ratio_ci(num: dict[str, list[float]], den: dict[str, list[float]], n: int = 2000,
             seed: int = 0) -> tuple[float, float, float]:
    """(ratio, 2.5 %, 97.5 %): the mean of ``num``'s episodes over the mean of ``den``'s, two controllers flown on
    the same tasks, with a paired bootstrap interval (each draw resamples the tasks once for both, then each
    task's episodes of each). Draws whose denominator is 0 are dropped; with none left, all three are NaN."""
    tasks = [t for t in den if t in num]
    rng = np.random.default_rng(seed)
    mean_den = np.mean([v for t in tasks for v in den[t]]) if tasks else 0.0
    if mean_den == 0:
        return float("nan"), float("nan"), float("nan")
    ratio = float(np.mean([v for t in tasks for v in num[t]]) / mean_den)
    draws = []
    for _ in range(n):
        picked = [tasks[i] for i in rng.choice(len(tasks), size=len(tasks))]
        a = np.mean([v for t in picked for v in rng.choice(num[t], size=len(num[t]))])
        b = np.mean([v for t in picked for v in rng.choice(den[t], size=len(den[t]))])
        if b > 0:
            draws.append(a / b)
    if not draws:
        return ratio, float("nan"), float("nan")
    return ratio, float(np.percentile(draws, 2.5)), float(np.percentile(draws, 97.5))


def _by_task(episodes: list[dict]) -> dict[str, list[float]]:
    out: dict[str, list[float]] = {}
    for e in episodes:
        out.setdefault(e["task"], []).append(float(e["success"]))
    return out


def success_cell(episodes: list[dict]) -> tuple[float, str]:
    """(success rate, ``"95 (82-100) of 40"``): the episodes' success % with its :func:`bootstrap_ci` interval
    over their tasks, as the held-out tables print it."""
    lo, hi = bootstrap_ci(_by_task(episodes))
    rate = float(np.mean([e["success"] for e in episodes]))
    return rate, f"{100 * rate:.0f} ({100 * lo:.0f}-{100 * hi:.0f}) of {len(episodes)}"


class ExpertRecorder:
    """The expert as a controller that also keeps, in ``family``'s padded layout, each observation it answered
    and its action: the held-out expert's state-action pairs, on which a BC policy's action error is measured
    (the regression's error on unseen tasks, apart from the drift of flying it in closed loop)."""

    def __init__(self, expert: Any, scenario: Any, family: str) -> None:
        from impact_env.transport.generate import FAMILY_LIMITS
        from impact_env.transport.task_observation import TaskObservation

        self.expert, self.pad = expert, TaskObservation(scenario, FAMILY_LIMITS[family])
        self.observations: list[np.ndarray] = []
        self.actions: list[np.ndarray] = []

    def reset(self, env: Any = None, seed: int | None = None) -> None:
        self.expert.reset(env, seed)

    def act(self, observation: np.ndarray, info: dict[str, Any] | None = None) -> np.ndarray:
        action = self.expert.act(observation, info)
        self.observations.append(self.pad(observation))
        self.actions.append(self.pad.pad_action(action))
        return action


def action_mse(policy: Any, observations: np.ndarray, actions: np.ndarray) -> float:
    """Mean squared error of ``policy.act`` (a batch of padded observations at once) against ``actions``, per
    action number (the unit of :func:`baselines.task_bc.train_task_bc`'s loss)."""
    return float(np.mean((policy.act(observations) - actions) ** 2))


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


def run_family(family: str, args: argparse.Namespace) -> None:
    """Build ``family``'s datasets from ``args.tasks`` (when stale), fly the expert on the held-out tasks, and
    train and fly one BC policy per training seed (the cells already in the store are skipped)."""
    import torch

    from baselines.task_bc import TaskBCConfig, TaskBCPolicy, train_task_bc
    from baselines.task_dataset import DatasetConfig, build_dataset, split_tasks
    from impact_env.results_store import CellStore
    from planners.expert import Expert
    from planners.task_filter import load_kept

    torch.set_num_threads(args.threads)
    tasks_dir = Path(args.tasks)
    store = CellStore(OUT / "cells.jsonl", key=cell_key)
    kept = load_kept(tasks_dir / family)
    names = [t[0].name for t in kept]
    train_names, held_names = split_tasks(names, args.heldout, 0)
    if set(train_names) & set(held_names):  # split_tasks promises disjoint sides; the table relies on it
        raise ImpactEnvError(f"tasks on both sides of the split: {sorted(set(train_names) & set(held_names))}")
    held = [t for t in kept if t[0].name in held_names]
    datasets = DATASETS / family
    split_file = datasets / "impact_env" / f"generated_{family}" / "split.json"
    built = json.loads(split_file.read_text()) if split_file.is_file() else {}
    wanted = {"tasks_dir": str(tasks_dir / family), "train": train_names, "heldout": held_names,
              "episodes_per_task": args.episodes_per_task, "env_options": NOISE}
    if any(built.get(k) != v for k, v in wanted.items()):
        start = time.perf_counter()
        build_dataset(family, tasks_dir / family,
                      DatasetConfig(episodes_per_task=args.episodes_per_task, heldout_share=args.heldout,
                                    env_options=NOISE, fly_heldout=False), out=datasets)
        print(f"{family}: datasets of {len(train_names)} training tasks built in {time.perf_counter() - start:.0f} s",
              flush=True)
    common = {"family": family, "tasks_dir": str(tasks_dir), "train_tasks": len(train_names),
              "heldout_tasks": held_names}
    pairs_file = datasets / "heldout_expert_pairs.npz"
    if store.get((family, str(tasks_dir), "expert", None)) is None:
        start = time.perf_counter()
        episodes, observations, actions = [], [], []
        for scenario, plan, _ in held:
            expert = ExpertRecorder(Expert(scenario, plan=plan), scenario, family)
            episodes += [fly_episode(scenario, expert, EVAL_SEED0 + k, None) for k in range(args.eval_episodes)]
            observations += expert.observations
            actions += expert.actions
        np.savez(pairs_file, observations=np.stack(observations), actions=np.stack(actions),
                 tasks=np.asarray(held_names))
        store.put({**common, "controller": "expert", "train_seed": None, "eval_wall_s": time.perf_counter() - start,
                   "heldout_zero_action_mse": float(np.mean(np.square(actions))), "episodes": episodes})
        print(f"{family}: expert held-out success {100 * np.mean([e['success'] for e in episodes]):.0f} % "
              f"({len(episodes)} episodes, {time.perf_counter() - start:.0f} s)", flush=True)
    hidden = tuple(int(w) for w in args.hidden.split(","))
    settings = {"epochs": args.epochs, "observation_noise": args.observation_noise, "hidden": list(hidden)}
    for seed in [int(s) for s in args.seeds.split(",")]:
        cell = store.get((family, str(tasks_dir), args.label, seed))
        if cell is not None:
            if cell.get("settings", settings) != settings:
                raise ImpactEnvError(f"{family} {args.label} seed {seed} was trained with {cell['settings']}, not "
                                     f"{settings}: give these settings another --label")
            continue
        run = train_task_bc(TaskBCConfig(family, datasets_dir=str(datasets), seed=seed, epochs=args.epochs,
                                         hidden=hidden, observation_noise=args.observation_noise,
                                         out=str(RUNS / f"{family}_{args.label}_s{seed}")))
        train = json.loads((run / "train.json").read_text())
        policy = TaskBCPolicy.load(run)
        heldout_mse = None
        if pairs_file.is_file():
            pairs = np.load(pairs_file)
            if sorted(pairs["tasks"].tolist()) == sorted(held_names):
                heldout_mse = action_mse(policy, pairs["observations"], pairs["actions"])
        start = time.perf_counter()
        episodes = [fly_episode(sc, policy, EVAL_SEED0 + k, family) for sc, _, _ in held
                    for k in range(args.eval_episodes)]
        store.put({**common, "controller": args.label, "train_seed": seed, "settings": settings,
                   "dataset_steps": train["steps"], "dataset_episodes": train["episodes"], "epochs": args.epochs,
                   "final_loss": train["final_loss"], "train_mse": train["train_mse"],
                   "heldout_action_mse": heldout_mse, "train_wall_s": train["wall_s"],
                   "eval_wall_s": time.perf_counter() - start, "episodes": episodes})
        ok = np.mean([e["success"] for e in episodes])
        print(f"{family}: {args.label} seed {seed}: action MSE {train['train_mse']:.4f} on the training steps, "
              f"{heldout_mse if heldout_mse is None else f'{heldout_mse:.4f}'} on the held-out expert's; "
              f"trained in {train['wall_s']:.0f} s, "
              f"held-out success {100 * ok:.0f} % ({len(episodes)} episodes)", flush=True)


def table() -> str:
    """The markdown table of every cell in the store: per family and task folder, the expert, then each BC label."""
    from impact_env.results_store import CellStore

    store = CellStore(OUT / "cells.jsonl", key=cell_key)
    rows = ["| family | controller | train / held-out tasks | held-out success % (95 % CI) | per training seed % | "
            "share of the expert's success (95 % CI) | robustness m (mean) | ms/step (median) | "
            "action MSE train / held-out | dataset steps | epochs | train wall s |", "|" + "---|" * 12]
    groups = list(dict.fromkeys(cell_key(c)[:2] for c in store))
    for group in groups:
        cells = [c for c in store if cell_key(c)[:2] == group]
        labels = ["expert"] + [lb for lb in dict.fromkeys(c["controller"] for c in cells) if lb != "expert"]
        expert = [e for c in cells if c["controller"] == "expert" for e in c["episodes"]]
        for label in labels:
            mine = [c for c in cells if c["controller"] == label]
            if not mine:
                continue
            eps = [e for c in mine for e in c["episodes"]]
            _, success = success_cell(eps)
            bc = label != "expert"
            per_seed = ", ".join(f"{100 * np.mean([e['success'] for e in c['episodes']]):.0f}" for c in mine)
            share = "-"
            if bc and expert:
                ratio, lo, hi = ratio_ci(_by_task(eps), _by_task(expert))
                share = "-" if np.isnan(ratio) else f"{ratio:.2f} ({lo:.2f}-{hi:.2f})"
            wall = f"{statistics.fmean(c['train_wall_s'] for c in mine):.0f}" if bc else "-"
            mse = "-"
            if not bc and mine[0].get("heldout_zero_action_mse") is not None:  # the error of always acting 0
                mse = f"zero action: {mine[0]['heldout_zero_action_mse']:.4f}"
            if bc and all(c.get("heldout_action_mse") is not None for c in mine):
                mse = (f"{statistics.fmean(c['train_mse'] for c in mine):.4f} / "
                       f"{statistics.fmean(c['heldout_action_mse'] for c in mine):.4f}")
            rows.append(
                f"| {group[0]} | {label}{f' ({len(mine)} seeds)' if bc else ''} | {mine[0]['train_tasks']} / "
                f"{len(mine[0]['heldout_tasks'])} | {success} | {per_seed if bc else '-'} | {share} | "
                f"{statistics.fmean(e['robustness_m'] for e in eps):+.3f} | "
                f"{statistics.median(e['ms_per_step'] for e in eps):.2f} | {mse} | "
                f"{mine[0]['dataset_steps'] if bc else '-'} | {mine[0]['epochs'] if bc else '-'} | {wall} |")
    return "\n".join(rows) + "\n"


def main(argv: list[str] | None = None) -> int:
    from impact_env.transport.generate import FAMILIES

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--families", default=",".join(FAMILIES))
    parser.add_argument("--tasks", default=str(TASKS), metavar="DIR",
                        help="folder of the kept tasks, one subfolder per family (default %(default)s)")
    parser.add_argument("--seeds", default="0,1,2", help="BC training seeds")
    parser.add_argument("--eval-episodes", type=int, default=5, help="env seeds per held-out task")
    parser.add_argument("--episodes-per-task", type=int, default=3, help="expert episodes per task in the datasets")
    parser.add_argument("--heldout", type=float, default=0.25, help="share of tasks held out")
    parser.add_argument("--label", default="bc", help="the BC policies' name in the cells and the table")
    parser.add_argument("--epochs", type=int, default=40)
    parser.add_argument("--hidden", default="256,256", help="hidden layer widths, comma-separated")
    parser.add_argument("--observation-noise", type=float, default=0.05,
                        help="Gaussian noise on standardised training observations, in standard deviations")
    parser.add_argument("--threads", type=int, default=1, help="torch threads of training")
    parser.add_argument("--table-only", action="store_true")
    args = parser.parse_args(argv)
    if not args.table_only:
        for family in args.families.split(","):
            run_family(family, args)
    from impact_env.results_store import write_atomic

    text = table()
    write_atomic(OUT / "table.md", text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
