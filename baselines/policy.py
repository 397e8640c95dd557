"""A trained stable-baselines3 model as an ``impact-env run`` controller: ``--controller path/to/model.zip``."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import numpy as np

from baselines import model_files, run_meta
from impact_env.errors import ControllerError
from impact_env.transport.core import ACTION_PER_ROBOT, OBS_PER_BODY


class SB3Controller:
    """Flies a saved PPO or SAC model in the central Gymnasium env.

    Beside ``model.zip`` it reads ``train.json`` (algorithm, whether the policy was trained per agent with
    parameter sharing) and ``vecnormalize.json`` (observation statistics) when they exist. Nothing in the
    folder is unpickled (:mod:`baselines.model_files`): the model's spaces are rebuilt from the scenario's
    environment. ``trust_pickle=True`` (``--trust-pickle``) also loads an old folder's ``vecnormalize.pkl``
    and any pickled entries of the zip, with a warning. A parameter-shared policy is queried once per robot
    with that robot's own observation (own body first).
    """

    name = "sb3"

    def __init__(self, scenario: Any, model_path: str | Path, trust_pickle: bool = False,
                 allow_other_scenario: bool = False) -> None:
        from gymnasium import spaces

        from impact_env.transport.core import TransportCore

        path = Path(model_path)
        self.model_path = path
        model_files.check_model_path(path)  # a folder, a FIFO or a link loop is named as such, not "missing"
        self.meta = model_files.read_train_json(path.parent)
        run_meta.check_scenario(self.meta, scenario, str(path), allow_other_scenario)
        self._warned = False
        self.scenario = scenario
        self.multiagent = bool(self.meta.get("multiagent"))
        self.tether = hasattr(scenario, "anchors")  # a tether station: discrete commands (baselines/tether.py)
        if self.tether:
            from baselines.tether import spaces_of

            obs_space, act_space, obs_size = spaces_of(scenario)
        else:
            core = TransportCore(scenario)
            n_actions = ACTION_PER_ROBOT * (1 if self.multiagent else core.n_robots)
            obs_space = spaces.Box(core.obs_low, core.obs_high, dtype=np.float32)
            act_space = spaces.Box(-1.0, 1.0, shape=(n_actions,), dtype=np.float32)
            obs_size = core.obs_size
        self.model = model_files.load_model(path, self.meta.get("algo"), obs_space, act_space, trust_pickle)
        self._normalization = model_files.load_normalization(path.parent, obs_size, trust_pickle)

    def _normalise(self, obs: np.ndarray) -> np.ndarray:
        return obs if self._normalization is None else self._normalization.apply(obs)

    def reset(self, env: Any, seed: int | None) -> None:
        if not self._warned:
            self._warned = True
            differences = run_meta.option_differences(self.meta, env.unwrapped.core)
            if differences:
                print(f"impact-env: warning: {self.model_path} was trained with other environment options ("
                      + "; ".join(differences) + ")", file=sys.stderr, flush=True)
        if self.tether:
            return
        self._n_bodies = len(env.unwrapped.scenario.bodies)
        self._n_robots = len(env.unwrapped.scenario.robots)

    def act(self, observation: np.ndarray, info: dict[str, Any]) -> np.ndarray:
        obs = np.asarray(observation, dtype=np.float32)
        if self.tether:
            action, _ = self.model.predict(self._normalise(obs), deterministic=True)
            return np.asarray(action, dtype=np.int64)
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


def make_sb3_controller(scenario: Any, model: str | None = None, trust_pickle: bool = False,
                        allow_other_scenario: bool = False, **_: Any) -> SB3Controller:
    if model is None:
        raise ControllerError("the sb3 controller needs a model: --controller path/to/model.zip")
    return SB3Controller(scenario, model, trust_pickle=trust_pickle, allow_other_scenario=allow_other_scenario)
