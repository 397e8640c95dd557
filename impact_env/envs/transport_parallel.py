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
from impact_env.envs.clock import EpisodeClock, check_max_cycles, check_render_options, reject_unknown, required
from impact_env.envs.core import ACTION_PER_ROBOT, TransportCore
from impact_env.envs.transport import SCENARIO_HINT
from impact_env.errors import ActionError
from impact_env.scenario import Scenario


class TransportParallelEnv(EpisodeClock, ParallelEnv, EzPickle):
    """The transport task with one agent per robot (agent names are the robots' names).

    ## Description
    The world, task and reward of :class:`~impact_env.envs.transport.TransportEnv`, with each robot an agent
    of a PettingZoo ``ParallelEnv``; ``raw_env`` and ``env`` are its AEC forms. Import it as
    ``from impact_env import transport_v0`` (PettingZoo's versioned module) or make it with
    ``pettingzoo``'s registry id ``impact_env/transport-v0``.

    ## Agents
    One per robot, named as the scenario names its robots (``R1``, ``R2``: the paper's names, which plans,
    the expert and plots use too). PettingZoo's ``api_test`` recommends ``<descriptor>_<number>`` names and
    warns ("We recommend agents to be named in the format ..."); the warning is harmless, the names are kept so
    that an agent is the robot of the same name everywhere.

    ## Action space
    Per agent ``Box(-1, 1, (3,), float32)``: its own body-frame Fx, Fy, torque as fractions of its limits
    (clipped; NaN raises :class:`~impact_env.errors.ActionError`). A missing agent action means zero thrust.

    ## Observation space
    Per agent the central layout of ``TransportEnv`` (7 numbers per body, then time left) with the agent's own
    body first and the other bodies after it in scenario order, so one shared policy can drive every robot.
    ``state()`` returns the central observation (``state_space``).

    ## Rewards
    All agents receive the same team reward: the STL robustness reward of ``TransportEnv``.

    ## Episode end
    All agents terminate together at the formula's horizon (``horizon_steps``); ``max_cycles`` truncates earlier
    if given (None: no earlier cut).

    ## Arguments
    The keywords of ``TransportEnv`` (same names as the CLI options), and:

    * ``scenario``: a shipped name, a path to a TOML file or a :class:`~impact_env.scenario.Scenario`; required.
    * ``reward_mode``: ``"dense"``, ``"sparse"`` or ``"conjuncts"``.
    * ``fuel_penalty``: reward cost per N s of fuel (>= 0).
    * ``restitution``: simulate with this restitution instead of the scenario's; None keeps it.
    * ``thrust_noise``: standard deviation of multiplicative thrust noise.
    * ``initial_position_noise_m``: objects start uniformly within this radius (m) of their position.
    * ``max_cycles``: truncate after this many steps (None: only the horizon ends an episode).
    * ``render_mode``: ``"rgb_array"``, ``"human"`` or None.
    * ``render_width_px``: width of the rendered frame.

    ## Metadata
    ``metadata["name"]`` is ``transport_<scenario>_v0`` (e.g. ``transport_corridor_v0``), so logs and
    SuperSuit wrappers tell the scenarios apart.

    ## Version history
    * v0: initial release (impact_env 0.1.0). In 0.2.0: explicit entry-point arguments, the per-scenario
      metadata name, the versioned module ``impact_env.transport_v0``; dynamics, reward and observations
      unchanged.
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 10, "name": "transport_v0",
                "is_parallelizable": True}

    def __init__(self, scenario: Scenario | str | None = None, reward_mode: str = "dense",
                 fuel_penalty: float = 0.0, restitution: float | None = None, thrust_noise: float = 0.0,
                 initial_position_noise_m: float = 0.0, max_cycles: int | None = None,
                 render_mode: str | None = None, render_width_px: int = 600, **unknown: Any) -> None:
        reject_unknown(unknown, type(self))
        EzPickle.__init__(self, scenario, reward_mode, fuel_penalty, restitution, thrust_noise,
                          initial_position_noise_m, max_cycles, render_mode, render_width_px)
        check_render_options(self.metadata, render_mode, render_width_px)
        check_max_cycles(max_cycles)
        scenario = required(scenario, "scenario", SCENARIO_HINT,
                            "impact_env.transport_v0.parallel_env(scenario='corridor')")
        self.core = TransportCore(scenario, reward_mode=reward_mode, fuel_penalty=fuel_penalty,
                                  restitution=restitution, thrust_noise=thrust_noise,
                                  initial_position_noise_m=initial_position_noise_m)
        self.scenario = self.core.scenario
        self.metadata = dict(self.metadata, render_fps=round(1.0 / self.scenario.control_period_s),
                             name=f"transport_{self.scenario.name}_v0")
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


def parallel_env(scenario: Scenario | str | None = None, reward_mode: str = "dense", fuel_penalty: float = 0.0,
                 restitution: float | None = None, thrust_noise: float = 0.0, initial_position_noise_m: float = 0.0,
                 max_cycles: int | None = None, render_mode: str | None = None,
                 render_width_px: int = 600, **unknown: Any) -> TransportParallelEnv:
    """The ParallelEnv; the arguments of :class:`TransportParallelEnv`."""
    return TransportParallelEnv(scenario, reward_mode, fuel_penalty, restitution, thrust_noise,
                                initial_position_noise_m, max_cycles, render_mode, render_width_px, **unknown)


def raw_env(scenario: Scenario | str | None = None, reward_mode: str = "dense", fuel_penalty: float = 0.0,
            restitution: float | None = None, thrust_noise: float = 0.0, initial_position_noise_m: float = 0.0,
            max_cycles: int | None = None, render_mode: str | None = None, render_width_px: int = 600, **unknown: Any):
    """The AEC form without the order-enforcing wrapper; the arguments of :class:`TransportParallelEnv`."""
    return parallel_to_aec_wrapper(parallel_env(scenario, reward_mode, fuel_penalty, restitution, thrust_noise,
                                                initial_position_noise_m, max_cycles, render_mode,
                                                render_width_px, **unknown))


def env(scenario: Scenario | str | None = None, reward_mode: str = "dense", fuel_penalty: float = 0.0,
        restitution: float | None = None, thrust_noise: float = 0.0, initial_position_noise_m: float = 0.0,
        max_cycles: int | None = None, render_mode: str | None = None, render_width_px: int = 600, **unknown: Any):
    """The AEC form, order-enforced (what ``pettingzoo.test.api_test`` expects); the arguments of
    :class:`TransportParallelEnv`."""
    return OrderEnforcingWrapper(raw_env(scenario, reward_mode, fuel_penalty, restitution, thrust_noise,
                                         initial_position_noise_m, max_cycles, render_mode, render_width_px, **unknown))
