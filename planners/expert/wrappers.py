"""Gymnasium wrapper that labels every observation with the expert's action, for imitation learning."""

from __future__ import annotations

from typing import Any

import gymnasium as gym

from impact_env.errors import EnvConfigError
from impact_env.transport.scenario import Scenario
from planners.expert.expert import Expert


class ExpertActionInfo(gym.Wrapper):
    """Adds ``info["expert_action"]``: what the expert would do in the observation just returned.

    The wrapped env is driven by whatever actions the user passes (a learner's, for DAgger), and the
    expert labels each state it visits. Args: ``env`` a TransportEnv (possibly wrapped); ``expert`` an
    :class:`~planners.expert.Expert` for the same scenario (built, with a fresh plan, if None).
    """

    def __init__(self, env: gym.Env, expert: Expert | None = None) -> None:
        super().__init__(env)
        scenario = getattr(env.unwrapped, "scenario", None)
        if not isinstance(scenario, Scenario):
            raise EnvConfigError(f"the expert labels a TransportEnv (an env with a Scenario), got "
                                 f"{type(env.unwrapped).__name__}")
        self.expert = expert or Expert(scenario)
        if self.expert.scenario.name != scenario.name:
            raise ValueError(f"expert is for {self.expert.scenario.name!r}, env runs {scenario.name!r}")

    def reset(self, **kwargs: Any):
        obs, info = self.env.reset(**kwargs)
        self.expert.reset()
        info["expert_action"] = self.expert.act(obs, info)
        return obs, info

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        if not (terminated or truncated):
            info["expert_action"] = self.expert.act(obs, info)
        return obs, reward, terminated, truncated, info
