"""PettingZoo environment: one agent per robot, a shared team reward.

Entry points follow PettingZoo's convention: :func:`parallel_env` (the ParallelEnv), :func:`raw_env` (its
AEC form without wrappers) and :func:`env` (the AEC form, order-enforced).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.utils import EzPickle, seeding
from pettingzoo import ParallelEnv
from pettingzoo.utils.conversions import parallel_to_aec_wrapper
from pettingzoo.utils.wrappers import OrderEnforcingWrapper

from impact_env.envs import render_support
from impact_env.envs.actions import numbers_of
from impact_env.envs.core import ACTION_PER_ROBOT, TransportCore
from impact_env.errors import ActionError, EnvConfigError
from impact_env.scenario import Scenario


class TransportParallelEnv(ParallelEnv, EzPickle):
    """The transport task with one agent per robot (agent names are the robots' names).

    Every agent has the same spaces: action ``Box(-1, 1, (3,))`` (its own body-frame Fx, Fy, torque as
    fractions of its limits) and an observation with the central layout of
    :class:`~impact_env.envs.transport.TransportEnv` (7 numbers per body, then time left) but with the
    agent's own body first and the other bodies after it in scenario order, so one shared policy can
    drive every robot. ``state()`` returns the central observation. All agents receive the same team
    reward (the STL robustness reward, see ``TransportEnv``) and terminate together at the formula's
    horizon; ``max_cycles`` truncates earlier if given. A missing agent action means zero thrust.
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 10, "name": "impact_env_transport_v0",
                "is_parallelizable": True}

    def __init__(self, scenario: Scenario | str = "corridor", reward_mode: str = "dense", fuel_penalty: float = 0.0,
                 restitution: float | None = None, thrust_noise: float = 0.0,
                 initial_position_noise_m: float = 0.0, max_cycles: int | None = None,
                 render_mode: str | None = None, render_width_px: int = 600) -> None:
        EzPickle.__init__(self, scenario, reward_mode, fuel_penalty, restitution, thrust_noise,
                          initial_position_noise_m, max_cycles, render_mode, render_width_px)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise EnvConfigError(f"render_mode must be one of {self.metadata['render_modes']} or None, "
                                 f"got {render_mode!r}")
        if max_cycles is not None and not (type(max_cycles) is int and max_cycles >= 1):
            raise EnvConfigError(f"max_cycles must be a positive integer or None, got {max_cycles!r}")
        if not (type(render_width_px) is int and 16 <= render_width_px <= 8192):
            raise EnvConfigError(f"render_width_px must be an integer in 16..8192, got {render_width_px!r}")
        self.core = TransportCore(scenario, reward_mode=reward_mode, fuel_penalty=fuel_penalty,
                                  restitution=restitution, thrust_noise=thrust_noise,
                                  initial_position_noise_m=initial_position_noise_m)
        self.scenario = self.core.scenario
        self.metadata = dict(self.metadata, render_fps=round(1.0 / self.scenario.control_period_s))
        self.max_cycles = max_cycles
        self.render_mode = render_mode
        self.render_width_px = render_width_px
        self.possible_agents = [r.name for r in self.scenario.robots]
        self.agents: list[str] = []
        obs_space = spaces.Box(self.core.obs_low, self.core.obs_high, dtype=np.float32)
        act_space = spaces.Box(-1.0, 1.0, shape=(ACTION_PER_ROBOT,), dtype=np.float32)
        self.observation_spaces = {a: obs_space for a in self.possible_agents}
        self.action_spaces = {a: act_space for a in self.possible_agents}
        self.state_space = spaces.Box(self.core.obs_low, self.core.obs_high, dtype=np.float32)
        self._zero_list = [0.0] * ACTION_PER_ROBOT
        self._agent_set = frozenset(self.possible_agents)
        self._renderer = None
        self.np_random, _ = seeding.np_random(None)

    def observation_space(self, agent: str) -> spaces.Box:
        return self.observation_spaces[agent]

    def action_space(self, agent: str) -> spaces.Box:
        return self.action_spaces[agent]

    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None):
        if seed is not None or not hasattr(self, "_seeded"):
            self.np_random, _ = seeding.np_random(seed)
            self._seeded = True
        self.core.reset(self.np_random)
        self.agents = list(self.possible_agents)
        self._cycles = 0
        if self.render_mode == "human":
            self.render()
        info = {"robustness": self.core.log.robustness, "is_success": self.core.log.robustness > 0.0,
                "impacts": [], "fuel_Ns": 0.0, "time_s": 0.0}
        return self._observations(), {a: dict(info) for a in self.agents}

    def _observations(self) -> dict[str, np.ndarray]:
        return {a: self.core.agent_observation(i) for i, a in enumerate(self.possible_agents) if a in self.agents}

    def state(self) -> np.ndarray:
        return self.core.observation()

    def step(self, actions: dict[str, Any]):
        if not isinstance(actions, Mapping):
            raise ActionError(f"actions must be a dict from agent name to action, got {type(actions).__name__}")
        unknown = [a for a in actions if a not in self._agent_set]
        if unknown:
            raise ActionError(f"actions for unknown agents {sorted(map(repr, unknown))}; agents are "
                              f"{self.possible_agents}")
        joint: list[float] = []
        for a in self.possible_agents:
            action = actions.get(a)
            joint += self._zero_list if action is None else numbers_of(action, ((ACTION_PER_ROBOT,),),
                                                                        f"actions[{a!r}]", "Fx, Fy, torque")
        reward, terminated, info = self.core.step(np.array(joint))
        self._cycles += 1
        truncated = not terminated and self.max_cycles is not None and self._cycles >= self.max_cycles
        agents = self.agents
        obs = self._observations()
        rewards = {a: reward for a in agents}
        terminations = {a: terminated for a in agents}
        truncations = {a: truncated for a in agents}
        infos = {a: dict(info) for a in agents}
        if terminated or truncated:
            self.agents = []
        if self.render_mode == "human":
            self.render()
        return obs, rewards, terminations, truncations, infos

    def render(self):
        if self.render_mode is None:
            return None
        if self.core.world is None:
            raise RuntimeError("call reset() before render()")
        return render_support.render(self)

    def close(self) -> None:
        render_support.close(self)


def parallel_env(**kwargs) -> TransportParallelEnv:
    """The ParallelEnv; keyword arguments as :class:`TransportParallelEnv`."""
    return TransportParallelEnv(**kwargs)


def raw_env(**kwargs):
    """The AEC form without the order-enforcing wrapper."""
    return parallel_to_aec_wrapper(TransportParallelEnv(**kwargs))


def env(**kwargs):
    """The AEC form, order-enforced: what ``pettingzoo.test.api_test`` expects."""
    return OrderEnforcingWrapper(raw_env(**kwargs))
