"""The residual world: the expert flies, and a learned correction is added to its command each step.

    env = ResidualEnv(TransportEnv("corridor", impact_velocity_noise_mps=0.02), Expert("corridor"), scale=0.2)

Each step the expert (:class:`planners.expert.Expert`, stateful: reset with the env and fed every observation
and ``info`` in order, exactly as when it flies alone) computes its command ``u`` for the observation, and the
agent's action ``a`` in [-1, 1] is added as ``clip(u + scale * a, -1, 1)`` (:func:`compose`), the action the
pymunk env executes. The agent observes the env's observation followed by ``u``, so it sees what it corrects.
A zero residual flies the expert's own episode exactly. :class:`ResidualController` flies a trained residual
policy on top of its expert wherever a controller is driven (:func:`impact_env.rollout.run_episode`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from impact_env.errors import ControllerError, EnvConfigError
from impact_env.transport.scenario import Scenario

__all__ = ["DEFAULT_SCALE", "ResidualController", "ResidualEnv", "compose", "residual_spaces"]

DEFAULT_SCALE = 0.2
"""The largest correction, as a fraction of each wrench limit (a residual of 1 adds 20 % of the limit)."""


def compose(command: np.ndarray, residual: np.ndarray, scale: float) -> np.ndarray:
    """The executed action ``clip(command + scale * clip(residual, -1, 1), -1, 1)`` (float32, shape of
    ``command``): the expert's command plus the correction, within the env's action box."""
    residual = np.clip(np.asarray(residual, dtype=np.float64), -1.0, 1.0)
    return np.clip(np.asarray(command, dtype=np.float64) + scale * residual, -1.0, 1.0).astype(np.float32)


def residual_spaces(env_observation_space: spaces.Box, n_actions: int) -> tuple[spaces.Box, spaces.Box]:
    """(observation space, action space) of the residual agent: the env's observation then the expert's
    command (``n_actions`` numbers in [-1, 1]); the correction in [-1, 1]^``n_actions``."""
    low = np.concatenate([env_observation_space.low, -np.ones(n_actions)]).astype(np.float32)
    high = np.concatenate([env_observation_space.high, np.ones(n_actions)]).astype(np.float32)
    return (spaces.Box(low, high, dtype=np.float32),
            spaces.Box(-1.0, 1.0, shape=(n_actions,), dtype=np.float32))


def _check_scale(scale: float) -> float:
    if not (isinstance(scale, (int, float)) and not isinstance(scale, bool) and 0 < scale <= 2):
        raise EnvConfigError(f"scale must be a number in (0, 2] (a fraction of the wrench limits), got {scale!r}")
    return float(scale)


class ResidualEnv(gym.Env):
    """A learned correction on top of the expert's command, in the pymunk transport world.

    ## Action space
    ``Box(-1, 1, (3 * n_robots,), float32)``: the correction ``a``; the env executes
    ``clip(u + scale * a, -1, 1)`` where ``u`` is the expert's command (:func:`compose`).

    ## Observation space
    ``Box(float32)`` of size ``7 * n_bodies + 1 + 3 * n_robots``: the TransportEnv's observation, then the
    expert's command ``u`` for it (zeros after the last step, when the expert is not asked).

    ## Rewards
    The TransportEnv's reward (its ``reward_mode``; dense by default: the per-step increment of the STL
    robustness, summing to the final robustness, m) minus ``action_penalty * mean(a**2)``, so that a zero
    correction is the safe start and a correction must pay for itself.

    ## Starting state, episode end
    The TransportEnv's (its noise options included); the expert is reset with it.

    ## Info
    The TransportEnv's, plus ``expert_action`` (the expert's command for the observation returned, as
    :class:`planners.expert.wrappers.ExpertActionInfo` has it) and, after a step, that step's ``residual`` (``a``
    clipped) and ``executed_action``.

    ## Arguments
    ``env``: a :class:`~impact_env.transport.gym_env.TransportEnv` (possibly wrapped); ``expert``: an
    :class:`~planners.expert.Expert` for its scenario; ``scale`` in (0, 2] (default :data:`DEFAULT_SCALE`);
    ``action_penalty`` >= 0.

    ## Version history
    * v0: initial release.
    """

    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(self, env: gym.Env, expert: Any, scale: float = DEFAULT_SCALE, action_penalty: float = 0.0) -> None:
        scenario = getattr(env.unwrapped, "scenario", None)
        if not isinstance(scenario, Scenario):
            raise EnvConfigError(f"the residual wraps a TransportEnv (an env with a Scenario), got "
                                 f"{type(env.unwrapped).__name__}")
        if expert.scenario.name != scenario.name:
            raise EnvConfigError(f"the expert is for {expert.scenario.name!r}, the env runs {scenario.name!r}")
        if not (isinstance(action_penalty, (int, float)) and np.isfinite(action_penalty) and action_penalty >= 0):
            raise EnvConfigError(f"action_penalty must be a finite number >= 0, got {action_penalty!r}")
        self.env, self.expert = env, expert
        self.scale, self.action_penalty = _check_scale(scale), float(action_penalty)
        if not (isinstance(env.observation_space, spaces.Box) and isinstance(env.action_space, spaces.Box)):
            raise EnvConfigError("the residual needs Box observation and action spaces (a central TransportEnv), got "
                                 f"{env.observation_space} and {env.action_space}")
        self.n_actions = int(env.action_space.shape[0])
        self.observation_space, self.action_space = residual_spaces(env.observation_space, self.n_actions)
        self._command = np.zeros(self.n_actions, dtype=np.float32)

    def _observe(self, obs: np.ndarray) -> np.ndarray:
        return np.concatenate([np.asarray(obs, dtype=np.float32), self._command]).astype(np.float32)

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        obs, info = self.env.reset(seed=seed, options=options)
        self.expert.reset(self.env, seed)
        self._command = np.clip(np.asarray(self.expert.act(obs, info), dtype=np.float32), -1.0, 1.0)
        info["expert_action"] = self._command.copy()
        return self._observe(obs), info

    def step(self, action):
        residual = np.clip(np.asarray(action, dtype=np.float32).reshape(self.n_actions), -1.0, 1.0)
        if not np.all(np.isfinite(residual)):
            raise EnvConfigError(f"the residual action must be finite, got {np.asarray(action)!r}")
        executed = compose(self._command, residual, self.scale)
        obs, reward, terminated, truncated, info = self.env.step(executed)
        reward = float(reward) - self.action_penalty * float(np.mean(residual.astype(np.float64) ** 2))
        if terminated or truncated:
            self._command = np.zeros(self.n_actions, dtype=np.float32)
        else:
            self._command = np.clip(np.asarray(self.expert.act(obs, info), dtype=np.float32), -1.0, 1.0)
        info.update(expert_action=self._command.copy(), residual=residual, executed_action=executed)
        return self._observe(obs), reward, terminated, truncated, info

    def close(self) -> None:
        self.env.close()


class ResidualController:
    """Flies a trained residual policy on top of its expert (the :class:`~impact_env.controllers.Controller`
    protocol): each step the expert's command plus ``scale`` times the policy's deterministic correction.

    ``run_dir`` is a folder :func:`baselines.residual.train_residual` wrote (``model.zip``, ``vecnormalize.json``,
    ``train.json``); nothing in it is unpickled (:mod:`baselines.model_files`). ``expert`` must be built for the
    run's scenario with the stack it was trained with (``train.json``'s ``stack``) for the numbers to mean what
    they meant in training; ``scale`` defaults to the run's."""

    name = "residual"

    def __init__(self, expert: Any, run_dir: str | Path, scale: float | None = None) -> None:
        from baselines import model_files, run_meta
        from impact_env.transport.core import TransportCore

        folder = Path(run_dir)
        model_files.check_model_path(folder / "model.zip")
        self.meta = model_files.read_train_json(folder)
        if self.meta.get("method") != "residual":
            raise ControllerError(f"{folder} holds no residual policy (its train.json has no method \"residual\"): "
                                  "train one with impact-env residual SCENARIO")
        run_meta.check_scenario(self.meta, expert.scenario, str(folder))
        self.expert = expert
        self.scale = _check_scale(float(self.meta["scale"]) if scale is None else scale)
        core = TransportCore(expert.scenario)
        n_actions = 3 * core.n_robots
        obs_space, act_space = residual_spaces(spaces.Box(core.obs_low, core.obs_high, dtype=np.float32), n_actions)
        self.model = model_files.load_model(folder / "model.zip", "ppo", obs_space, act_space)
        self._normalization = model_files.load_normalization(folder, int(obs_space.shape[0]))
        self.residuals: list[np.ndarray] = []  # this episode's corrections, for |a| statistics

    def reset(self, env: Any, seed: int | None) -> None:
        self.expert.reset(env, seed)
        self.residuals = []

    def act(self, observation: np.ndarray, info: dict[str, Any]) -> np.ndarray:
        command = np.clip(np.asarray(self.expert.act(observation, info), dtype=np.float32), -1.0, 1.0)
        x = np.concatenate([np.asarray(observation, dtype=np.float32), command])
        if self._normalization is not None:
            x = self._normalization.apply(x)
        residual, _ = self.model.predict(x, deterministic=True)
        residual = np.clip(np.asarray(residual, dtype=np.float32), -1.0, 1.0)
        self.residuals.append(residual)
        return compose(command, residual, self.scale)
