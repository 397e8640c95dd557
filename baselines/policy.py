"""A trained stable-baselines3 model as an ``impact-env run`` controller: ``--controller path/to/model.zip``."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from impact_env.envs.core import OBS_PER_BODY
from impact_env.errors import ImpactEnvError


class SB3Controller:
    """Flies a saved PPO or SAC model in the central Gymnasium env.

    Beside ``model.zip`` it reads ``train.json`` (algorithm, whether the policy was trained per agent with
    parameter sharing) and ``vecnormalize.pkl`` (observation statistics) when they exist. A parameter-
    shared policy is queried once per robot with that robot's own observation (own body first).
    """

    name = "sb3"

    def __init__(self, scenario: Any, model_path: str | Path) -> None:
        from stable_baselines3 import PPO, SAC

        path = Path(model_path)
        if not path.is_file():
            raise ImpactEnvError(f"model file {str(path)!r} does not exist")
        meta_path = path.parent / "train.json"
        self.meta = json.loads(meta_path.read_text()) if meta_path.is_file() else {}
        algo = self.meta.get("algo")
        loaders = [{"ppo": PPO, "sac": SAC}[algo]] if algo in ("ppo", "sac") else [PPO, SAC]
        for cls in loaders:
            try:
                self.model = cls.load(str(path), device="cpu")
                break
            except Exception as exc:  # the other algorithm's file: try the next loader
                error = exc
        else:
            raise ImpactEnvError(f"{path} is not a PPO or SAC model saved by stable-baselines3: {error}")
        self.scenario = scenario
        self.multiagent = bool(self.meta.get("multiagent"))
        self._obs_rms = None
        stats = path.parent / "vecnormalize.pkl"
        if stats.is_file():
            import pickle

            with open(stats, "rb") as f:
                vn = pickle.load(f)
            self._obs_rms, self._clip, self._eps = vn.obs_rms, vn.clip_obs, vn.epsilon

    def _normalise(self, obs: np.ndarray) -> np.ndarray:
        if self._obs_rms is None:
            return obs
        return np.clip((obs - self._obs_rms.mean) / np.sqrt(self._obs_rms.var + self._eps), -self._clip, self._clip)

    def reset(self, env: Any, seed: int | None) -> None:
        self._n_bodies = len(env.unwrapped.scenario.bodies)
        self._n_robots = len(env.unwrapped.scenario.robots)

    def act(self, observation: np.ndarray, info: dict[str, Any]) -> np.ndarray:
        obs = np.asarray(observation, dtype=np.float32)
        if not self.multiagent:
            action, _ = self.model.predict(self._normalise(obs), deterministic=True)
            return np.asarray(action, dtype=np.float32)
        bodies = obs[:-1].reshape(self._n_bodies, OBS_PER_BODY)
        out = []
        for i in range(self._n_robots):
            order = [i] + [j for j in range(self._n_bodies) if j != i]
            agent_obs = np.append(bodies[order].reshape(-1), obs[-1]).astype(np.float32)
            action, _ = self.model.predict(self._normalise(agent_obs), deterministic=True)
            out.append(np.asarray(action, dtype=np.float32))
        return np.concatenate(out)


def make_sb3_controller(scenario: Any, model: str | None = None, **_: Any) -> SB3Controller:
    if model is None:
        raise ImpactEnvError("the sb3 controller needs a model: --controller path/to/model.zip")
    return SB3Controller(scenario, model)
