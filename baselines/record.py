"""Expert demonstrations as a Minari dataset (Farama's format for offline RL): ``impact-env record``.

The expert flies seeded episodes in the Gymnasium env (made with ``gym.make`` so the dataset carries the
env spec) and each episode is stored whole through ``minari.create_dataset_from_buffers``. Minari's own
``DataCollector`` is not used: it needs jax only to append step data, a heavy dependency for this.
Datasets go under the id ``impact_env/<scenario>/expert-v0`` to Minari's own folder (``$MINARI_DATASETS_PATH``,
else ``~/.minari/datasets``), so ``minari.load_dataset("impact_env/corridor/expert-v0")`` finds them with no
settings; ``out`` puts them elsewhere (then load with ``MINARI_DATASETS_PATH=out``).

Every step keeps the infos that matter (``ep.infos``, arrays of ``steps + 1`` values, the reset first):
``robustness`` (the online STL estimate, m; the last value is the episode's), ``is_success``, ``impacts``
(robot-object impacts that ended in the step), ``contacts`` (every contact that ended in the step, walls and
robot-robot included), ``fuel_Ns`` (cumulative) and ``time_s``.
"""

from __future__ import annotations

import os
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from impact_env import GYM_IDS
from impact_env.errors import ImpactEnvError
from impact_env.transport.scenario import load_scenario

INFO_KEYS = ("robustness", "is_success", "impacts", "contacts", "fuel_Ns", "time_s")


def dataset_id(scenario_name: str) -> str:
    return f"impact_env/{scenario_name}/expert-v0"


def datasets_path(out: str | Path | None = None) -> Path:
    """Where datasets go: ``out``, else Minari's default (``$MINARI_DATASETS_PATH`` or ``~/.minari/datasets``)."""
    if out is not None:
        return Path(out).resolve()
    return Path(os.environ.get("MINARI_DATASETS_PATH") or Path.home() / ".minari" / "datasets")


def use_datasets_path(out: str | Path | None) -> None:
    """Point Minari at ``out`` (it reads the variable on every call); leave its default alone when None."""
    if out is not None:
        os.environ["MINARI_DATASETS_PATH"] = str(Path(out).resolve())


def step_infos(info: dict[str, Any], robots: set[str], objects: set[str]) -> dict[str, Any]:
    """The per-step infos stored in the dataset (see the module docstring)."""
    events = info.get("impacts", [])
    hits = sum(1 for e in events if {e["a"], e["b"]} & robots and {e["a"], e["b"]} & objects)
    return {"robustness": float(info["robustness"]), "is_success": bool(info["is_success"]), "impacts": int(hits),
            "contacts": len(events), "fuel_Ns": float(info["fuel_Ns"]), "time_s": float(info["time_s"])}


def record(scenario: str, episodes: int, out: str | Path | None = None, plan_path: str | None = None,
           env_options: dict[str, Any] | None = None, seed: int = 0, quiet: bool = False) -> Any:
    """Record ``episodes`` expert episodes (seeds ``seed``, ``seed + 1``, ...), a line each unless ``quiet``;
    returns the MinariDataset. The datasets folder is checked before the first episode."""
    import gymnasium as gym

    from impact_env.results_store import check_output_folder

    check_output_folder(datasets_path(out), "--out")
    use_datasets_path(out)
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
    robots, objects = {r.name for r in sc.robots}, {o.name for o in sc.objects}
    buffers = []
    for k in range(episodes):
        obs, info = env.reset(seed=seed + k)
        expert.reset()
        observations, actions, rewards, terminations, truncations = [obs], [], [], [], []
        infos = {key: [value] for key, value in step_infos(info, robots, objects).items()}
        done = False
        while not done:
            action = expert.act(obs, info)
            obs, reward, terminated, truncated, info = env.step(action)
            observations.append(obs)
            actions.append(action)
            rewards.append(reward)
            terminations.append(terminated)
            truncations.append(truncated)
            for key, value in step_infos(info, robots, objects).items():
                infos[key].append(value)
            done = terminated or truncated
        buffers.append(EpisodeBuffer(id=k, seed=seed + k, observations=observations, actions=actions,
                                     rewards=rewards, terminations=terminations, truncations=truncations,
                                     infos={key: np.asarray(values) for key, values in infos.items()}))
        if not quiet:
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
