"""Expert demonstrations as a Minari dataset (Farama's format for offline RL): ``impact-env record``.

The expert flies seeded episodes in the Gymnasium env (made with ``gym.make`` so the dataset carries the
env spec) and each episode is stored whole through ``minari.create_dataset_from_buffers``. Minari's own
``DataCollector`` is not used: it needs jax only to append step data, a heavy dependency for this.
Datasets go to ``<out>/`` (Minari's ``MINARI_DATASETS_PATH``) under the id
``impact_env/<scenario>/expert-v0``; load them with ``minari.load_dataset`` and the same path.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from impact_env import GYM_IDS
from impact_env.errors import ImpactEnvError
from impact_env.scenario import load_scenario


def dataset_id(scenario_name: str) -> str:
    return f"impact_env/{scenario_name}/expert-v0"


def record(scenario: str, episodes: int, out: str | Path, plan_path: str | None = None,
           env_options: dict[str, Any] | None = None, seed: int = 0) -> Any:
    """Record ``episodes`` expert episodes (seeds ``seed``, ``seed + 1``, ...); returns the MinariDataset."""
    import gymnasium as gym

    os.environ["MINARI_DATASETS_PATH"] = str(Path(out).resolve())
    import minari
    from minari.data_collector.episode_buffer import EpisodeBuffer

    from planners.expert import Expert
    from planners.plan import Plan

    if episodes < 1:
        raise ImpactEnvError(f"episodes must be >= 1, got {episodes}")
    sc = load_scenario(scenario)
    env_id = next((i for i, name in GYM_IDS.items() if name == sc.name), None)
    kwargs = dict(env_options or {})
    env = gym.make(env_id, **kwargs) if env_id else gym.make("impact_env/Transport-v0", scenario=scenario, **kwargs)
    expert = Expert(sc, plan=Plan.load(plan_path) if plan_path else None)
    buffers = []
    for k in range(episodes):
        obs, info = env.reset(seed=seed + k)
        expert.reset()
        observations, actions, rewards, terminations, truncations = [obs], [], [], [], []
        done = False
        while not done:
            action = expert.act(obs, info)
            obs, reward, terminated, truncated, info = env.step(action)
            observations.append(obs)
            actions.append(action)
            rewards.append(reward)
            terminations.append(terminated)
            truncations.append(truncated)
            done = terminated or truncated
        buffers.append(EpisodeBuffer(id=k, seed=seed + k, observations=observations, actions=actions,
                                     rewards=rewards, terminations=terminations, truncations=truncations))
        print(f"  episode {k + 1}/{episodes}: robustness {info['robustness']:+.3f} "
              f"({'success' if info['is_success'] else 'failure'})", flush=True)
    name = dataset_id(sc.name)
    if name in minari.list_local_datasets():
        minari.delete_dataset(name)
    with warnings.catch_warnings():  # Minari nags about metadata this package has no value for
        warnings.filterwarnings("ignore", message=r"`(code_permalink|author_email|eval_env)` is set to None")
        dataset = minari.create_dataset_from_buffers(
            dataset_id=name, buffer=buffers, env=env, algorithm_name="impact_env expert (MILP plan + replanner + MPC)",
            author="impact_env", description=f"Expert demonstrations on {sc.name}: {sc.description}",
            data_format="hdf5")
    env.close()
    return dataset


def mean_return(dataset) -> float:
    return float(np.mean([ep.rewards.sum() for ep in dataset.iterate_episodes()]))
