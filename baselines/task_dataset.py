"""Expert demonstrations on generated tasks, as one Minari dataset per family: ``impact-env dataset``.

    train, heldout = build_dataset("gaps", "results/task_generator/gaps", out="datasets")

Reads a folder of kept tasks and their plans (written by ``impact-env filter``, :mod:`planners.task_filter`),
flies each task's plan with the expert for ``episodes_per_task`` env seeds, and stores the episodes in two
Minari datasets: ``impact_env/generated_<family>/expert-v0`` (the training tasks) and
``impact_env/generated_<family>/heldout-v0`` (the held-out tasks, never to be trained on; their expert
episodes are the reference a learned policy is compared with).

Which tasks are held out is fixed by the split seed and the task's name alone:
``sha256("<split_seed>/<name>")`` read as a number in [0, 1) below ``heldout_share``. So a task stays on its
side of the split when more tasks are added to the folder.

Observations and actions are the family's padded goal-conditioned layout
(:class:`impact_env.transport.task_observation.TaskObservation`): every task of a family has the same
spaces, so one dataset holds them all. Per step the infos keep ``task_seed`` (the generator's seed of the
episode's task), ``robustness``, ``is_success``, ``impacts``, ``contacts``, ``fuel_Ns`` and ``time_s``
(:func:`baselines.record.step_infos`). Minari's ``DataCollector`` is not used (see :mod:`baselines.record`).
"""

from __future__ import annotations

import hashlib
import json
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from baselines.record import datasets_path, step_infos, use_datasets_path
from impact_env.config_checks import check_flag, check_instance, check_integer, check_number, fail
from impact_env.errors import ImpactEnvError

__all__ = ["DatasetConfig", "build_dataset", "dataset_ids", "is_heldout", "split_tasks"]


@dataclass(frozen=True)
class DatasetConfig:
    """How the expert's episodes of a family's kept tasks become its datasets."""

    episodes_per_task: int = 1
    """Expert episodes per task (env seeds ``seed``, ``seed + 1``, ...)."""
    seed: int = 0
    """The env seed of each task's first episode."""
    quiet: bool = False
    """No line per episode."""
    heldout_share: float = 0.2
    """The share of tasks held out (in [0, 1))."""
    split_seed: int = 0
    """The seed of the held-out split."""
    max_tasks: int | None = None
    """Use at most this many kept tasks (in seed order); None: all."""
    env_options: dict[str, Any] | None = None
    """Options of the TransportEnv the expert flies in (e.g. ``{"thrust_noise": 0.05}``); None: nominal."""
    fly_heldout: bool = True
    """Fly the held-out tasks into the held-out dataset; False: only write their names in ``split.json`` (a
    benchmark that flies the expert on them itself, at other env seeds, need not pay for these episodes)."""

    def __post_init__(self) -> None:
        check_integer(self, "episodes_per_task", ImpactEnvError, low=1)
        check_integer(self, "seed", ImpactEnvError, low=0)
        check_flag(self, "quiet", ImpactEnvError)
        check_number(self, "heldout_share", ImpactEnvError, low=0, high=1)
        if self.heldout_share == 1:
            fail("DatasetConfig.heldout_share", self.heldout_share,
                 "< 1 (some tasks must be left to train on)", ImpactEnvError)
        check_integer(self, "split_seed", ImpactEnvError, low=0)
        check_integer(self, "max_tasks", ImpactEnvError, low=1, none="all")
        check_instance(self, "env_options", ImpactEnvError, dict, what="a dict of TransportEnv options",
                       none="nominal")
        check_flag(self, "fly_heldout", ImpactEnvError)


def dataset_ids(family: str) -> tuple[str, str]:
    """(training, held-out) Minari dataset ids of ``family``."""
    return f"impact_env/generated_{family}/expert-v0", f"impact_env/generated_{family}/heldout-v0"


def is_heldout(name: str, share: float, split_seed: int = 0) -> bool:
    """Whether task ``name`` is held out (see the module docstring): a function of the name and seed only."""
    digest = hashlib.sha256(f"{split_seed}/{name}".encode()).digest()
    return int.from_bytes(digest[:8], "big") / 2**64 < share


def split_tasks(names: list[str], share: float, split_seed: int = 0) -> tuple[list[str], list[str]]:
    """(training, held-out) names, each in the given order. With two or more tasks and ``share > 0`` at least
    one is held out and one is trained on (the one whose hash is lowest, or highest, moves side)."""
    held = [n for n in names if is_heldout(n, share, split_seed)]
    if len(names) >= 2 and share > 0:
        keys = {n: hashlib.sha256(f"{split_seed}/{n}".encode()).digest() for n in names}
        if not held:
            held = [min(names, key=keys.__getitem__)]
        elif len(held) == len(names):
            held.remove(max(names, key=keys.__getitem__))
    return [n for n in names if n not in held], held


def _episodes(family: str, tasks: list, config: DatasetConfig, first_id: int = 0) -> tuple[list, list[dict]]:
    from minari.data_collector.episode_buffer import EpisodeBuffer

    from impact_env.transport.generate import FAMILY_LIMITS
    from impact_env.transport.gym_env import TransportEnv
    from impact_env.transport.task_observation import TaskObservation
    from planners.expert import Expert

    buffers: list[EpisodeBuffer] = []
    summaries: list[dict] = []
    for scenario, plan, verdict in tasks:
        env = TransportEnv(scenario, **(config.env_options or {}))
        pad = TaskObservation(scenario, FAMILY_LIMITS[family])
        expert = Expert(scenario, plan=plan)
        robots, objects = {r.name for r in scenario.robots}, {o.name for o in scenario.objects}
        for seed in range(config.seed, config.seed + config.episodes_per_task):
            obs, info = env.reset(seed=seed)
            expert.reset()
            observations, actions, rewards, terminations, truncations = [pad(obs)], [], [], [], []
            infos = {key: [value] for key, value in step_infos(info, robots, objects).items()}
            done = False
            while not done:
                action = expert.act(obs, info)
                obs, reward, terminated, truncated, info = env.step(action)
                observations.append(pad(obs))
                actions.append(pad.pad_action(action))
                rewards.append(reward)
                terminations.append(terminated)
                truncations.append(truncated)
                for key, value in step_infos(info, robots, objects).items():
                    infos[key].append(value)
                done = terminated or truncated
            infos["task_seed"] = [int(verdict["seed"])] * len(observations)
            buffers.append(EpisodeBuffer(id=first_id + len(buffers), seed=seed, observations=observations,
                                         actions=actions, rewards=rewards, terminations=terminations,
                                         truncations=truncations,
                                         infos={key: np.asarray(values) for key, values in infos.items()}))
            summaries.append({"task": scenario.name, "seed": seed, "success": bool(info["is_success"]),
                              "robustness_m": float(info["robustness"]), "steps": len(actions)})
            if not config.quiet:
                print(f"  {scenario.name} seed {seed}: robustness {info['robustness']:+.3f} "
                      f"({'success' if info['is_success'] else 'failure'})", flush=True)
        env.close()
    return buffers, summaries


def build_dataset(family: str, tasks_dir: str | Path, config: DatasetConfig | None = None,
                  out: str | Path | None = None) -> tuple[Any, Any]:
    """Build the (training, held-out) MinariDatasets of ``family`` from the kept tasks in ``tasks_dir`` (see the
    module docstring; the held-out one is None when ``config.fly_heldout`` is False); ``out`` is where datasets
    go (default: Minari's own folder). Also writes
    ``<out>/impact_env/generated_<family>/split.json``: the names of both sides, the split's settings and the
    expert's per-episode success and robustness."""
    use_datasets_path(out)
    import minari

    from impact_env.transport.generate import FAMILIES, FAMILY_LIMITS
    from impact_env.transport.task_observation import TaskObservation
    from planners.task_filter import load_kept

    config = config or DatasetConfig()
    if family not in FAMILIES:
        raise ImpactEnvError(f"unknown task family {family!r}; families: {', '.join(FAMILIES)}")
    kept = [t for t in load_kept(tasks_dir) if t[2]["family"] == family]
    if config.max_tasks is not None:
        kept = kept[:config.max_tasks]
    if len(kept) < 2:
        raise ImpactEnvError(f"{tasks_dir} has {len(kept)} kept {family} task(s); a dataset and its held-out split "
                             "need at least 2 (filter more seeds: impact-env filter --seeds A:B)")
    train_names, held_names = split_tasks([t[0].name for t in kept], config.heldout_share, config.split_seed)
    obs_space, act_space = TaskObservation(kept[0][0], FAMILY_LIMITS[family]).spaces()
    datasets: list[Any] = []  # minari's datasets
    summary: dict[str, Any] = {}
    for dataset_id, names in zip(dataset_ids(family), (train_names, held_names)):
        if not names or (dataset_id == dataset_ids(family)[1] and not config.fly_heldout):
            if dataset_id in minari.list_local_datasets():
                minari.delete_dataset(dataset_id)  # an older build's episodes of another split would mislead
            datasets.append(None)
            continue
        buffers, episodes = _episodes(family, [t for t in kept if t[0].name in names], config)
        summary[dataset_id] = episodes
        if dataset_id in minari.list_local_datasets():
            minari.delete_dataset(dataset_id)
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=r"`(code_permalink|author_email|eval_env)` is set to None")
            warnings.filterwarnings("ignore", message=r"env_spec is None")  # one dataset, many tasks: no one env
            datasets.append(minari.create_dataset_from_buffers(
                dataset_id=dataset_id, buffer=buffers, observation_space=obs_space, action_space=act_space,
                algorithm_name="impact_env expert (MILP plan + replanner + MPC)", author="impact_env",
                description=f"Expert episodes on {len(names)} generated {family} tasks "
                            f"({'held out' if dataset_id.endswith('heldout-v0') else 'training'} side of split seed "
                            f"{config.split_seed}); observations padded to {FAMILY_LIMITS[family]}",
                data_format="hdf5"))
    folder = datasets_path(out) / "impact_env" / f"generated_{family}"
    folder.mkdir(parents=True, exist_ok=True)
    from impact_env.results_store import write_atomic

    write_atomic(folder / "split.json", json.dumps({
        "family": family, "tasks_dir": str(tasks_dir), "split_seed": config.split_seed,
        "heldout_share": config.heldout_share, "episodes_per_task": config.episodes_per_task,
        "env_options": config.env_options or {}, "fly_heldout": config.fly_heldout, "train": train_names,
        "heldout": held_names,
        "episodes": summary}, indent=1))
    return datasets[0], datasets[1]
