"""PettingZoo environment: one agent per robot, a shared team reward.

Entry points follow PettingZoo's convention: :func:`parallel_env` (the ParallelEnv), :func:`raw_env` (its
AEC form without wrappers) and :func:`env` (the AEC form, order-enforced).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo.utils.conversions import parallel_to_aec_wrapper
from pettingzoo.utils.wrappers import OrderEnforcingWrapper

from impact_env.env_shell import ParallelShell, required, time_left
from impact_env.errors import ActionError
from impact_env.transport import native
from impact_env.transport.actions import numbers_of
from impact_env.transport.core import ACTION_PER_ROBOT, TransportCore
from impact_env.transport.gym_env import SCENARIO_HINT
from impact_env.transport.rendering import Renderer, RenderFrame, frame_of
from impact_env.transport.scenario import Scenario

_AGENT_SHAPE = (ACTION_PER_ROBOT,)

# what the module-level entry points make without arguments, as pettingzoo.butterfly.pistonball_v6.env() does, so
# PettingZoo's own tests (api_test, parallel_api_test, max_cycles_test) run on impact_env.transport_v0 as it is
DEFAULT_SCENARIO = "corridor"


class TransportParallelEnv(ParallelShell):
    """The transport task with one agent per robot (agent names are the robots' names).

    ## Description
    The world, task and reward of :class:`~impact_env.transport.gym_env.TransportEnv`, with each robot an agent
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

    * ``scenario``: a shipped name, a path to a TOML file or a :class:`~impact_env.transport.scenario.Scenario`;
      required by the class; the module's ``parallel_env``, ``env`` and ``raw_env`` default to ``"corridor"``.
    * ``reward_mode``: ``"dense"``, ``"sparse"`` or ``"conjuncts"``.
    * ``fuel_penalty``: reward cost per N s of fuel (>= 0).
    * ``restitution``: simulate with this restitution instead of the scenario's; None keeps it.
    * ``thrust_noise``: standard deviation of multiplicative thrust noise.
    * ``initial_position_noise_m``: objects start uniformly within this radius (m) of their position.
    * ``max_cycles``: truncate after this many steps (None: only the horizon ends an episode).
    * ``render_mode``: ``"rgb_array"``, ``"human"`` or None.
    * ``render_width_px``: width of the rendered frame.
    * ``impact_velocity_noise_mps``: after each robot-object impact, a uniform error in [-this, this] m/s per
      axis on the object's velocity, drawn from the reset seed (see ``TransportEnv``).

    ## Metadata
    ``metadata["name"]`` is ``transport_<scenario>_v0`` (e.g. ``transport_corridor_v0``), so logs and
    SuperSuit wrappers tell the scenarios apart.

    ## Version history
    * v0: initial release (impact_env 0.1.0). In 0.3.0 the module's entry points default to the corridor (so
      ``max_cycles_test(transport_v0)`` runs); no episode changes. In 0.2.0: explicit entry-point arguments,
      the per-scenario metadata name, the versioned module ``impact_env.transport_v0``; dynamics, reward and
      observations unchanged.
    """

    metadata: dict[str, Any] = {"render_modes": ["human", "rgb_array"], "render_fps": 10, "name": "transport_v0",
                "is_parallelizable": True}

    def __init__(self, scenario: Scenario | str | None = None, reward_mode: str = "dense",
                 fuel_penalty: float = 0.0, restitution: float | None = None, thrust_noise: float = 0.0,
                 initial_position_noise_m: float = 0.0, max_cycles: int | None = None,
                 render_mode: str | None = None, render_width_px: int = 600,
                 impact_velocity_noise_mps: float = 0.0, **unknown: Any) -> None:
        self._open(unknown, (scenario, reward_mode, fuel_penalty, restitution, thrust_noise, initial_position_noise_m,
                             max_cycles, render_mode, render_width_px, impact_velocity_noise_mps),
                   render_mode, render_width_px, max_cycles)
        scenario = required(scenario, "scenario", SCENARIO_HINT,
                            "impact_env.transport_v0.parallel_env(scenario='corridor')")
        self.core = TransportCore(scenario, reward_mode=reward_mode, fuel_penalty=fuel_penalty,
                                  restitution=restitution, thrust_noise=thrust_noise,
                                  initial_position_noise_m=initial_position_noise_m,
                                  impact_velocity_noise_mps=impact_velocity_noise_mps)
        self.scenario = self.core.scenario
        self.metadata = dict(self.metadata, render_fps=round(1.0 / self.scenario.control_period_s),
                             name=f"transport_{self.scenario.name}_v0")
        self._set_agents([r.name for r in self.scenario.robots],
                         spaces.Box(-1.0, 1.0, shape=(ACTION_PER_ROBOT,), dtype=np.float32))
        self._agent_set = frozenset(self.possible_agents)
        self._agent_tuple = tuple(self.possible_agents)
        self._observations_shape = (self.core.n_robots, self.core.obs_size)
        self._zero_action = np.zeros(ACTION_PER_ROBOT)

    def _joint_action(self, actions: dict[str, Any]) -> list[Any]:
        """The core's action: one (3,) action per robot in agent order, zeros for a missing agent (the Python
        path of TransportCore.step_agents, with the errors)."""
        if not isinstance(actions, Mapping):
            raise ActionError(f"actions must be a dict from agent name to action, got {type(actions).__name__}")
        unknown = [a for a in actions if a not in self._agent_set]
        if unknown:
            raise ActionError(f"actions for unknown agents {sorted(map(repr, unknown))}; agents are "
                              f"{self.possible_agents}")
        joint = [actions.get(a) for a in self.possible_agents]
        for i, action in enumerate(joint):
            joint[i] = self._zero_action if action is None else numbers_of(
                action, (_AGENT_SHAPE,), f"actions[{self.possible_agents[i]!r}]", "Fx, Fy, torque")
        return joint

    def _observations(self) -> dict[str, np.ndarray]:
        """Every live agent's observation: the rows of one new array, each a permutation of the central one."""
        agents = self.agents
        if len(agents) == len(self._agent_tuple):  # every agent lives (they end together), in the same order
            return self.core.agent_observation_dict(self._agent_tuple)
        return {a: obs for a, obs in zip(self.possible_agents, self.core.agent_observations()) if a in agents}

    def step(self, actions: dict[str, Any]):
        """ParallelShell.step, with the per-agent dicts built in C where it is built (the same dicts)."""
        core = self.core
        reward, terminated, info = core.step_agents(actions, self._agent_tuple, self._joint_action)
        self._cycles += 1
        truncated = not terminated and self.max_cycles is not None and self._cycles >= self.max_cycles
        agents = self.agents
        outputs = native.parallel_outputs  # built with the core's observer
        if outputs is not None and core._observer is not None and len(agents) == core.n_robots:
            # every agent lives: they end together
            obs, rewards, terminations, truncations, infos = outputs(
                core._observer, time_left(core), np.empty(self._observations_shape, np.float32), self._agent_tuple,
                agents, reward, terminated, truncated, info)
        else:
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

    def _new_renderer(self, render_mode: str) -> Renderer:
        return Renderer(self.scenario, render_mode, width_px=self.render_width_px, fps=self.metadata["render_fps"])

    def _frame(self) -> RenderFrame:
        return frame_of(self.core)


def parallel_env(scenario: Scenario | str = DEFAULT_SCENARIO, reward_mode: str = "dense", fuel_penalty: float = 0.0,
                 restitution: float | None = None, thrust_noise: float = 0.0, initial_position_noise_m: float = 0.0,
                 max_cycles: int | None = None, render_mode: str | None = None,
                 render_width_px: int = 600, impact_velocity_noise_mps: float = 0.0,
                 **unknown: Any) -> TransportParallelEnv:
    """The ParallelEnv; the arguments of :class:`TransportParallelEnv`."""
    return TransportParallelEnv(scenario, reward_mode, fuel_penalty, restitution, thrust_noise,
                                initial_position_noise_m, max_cycles, render_mode, render_width_px,
                                impact_velocity_noise_mps, **unknown)


def raw_env(scenario: Scenario | str = DEFAULT_SCENARIO, reward_mode: str = "dense", fuel_penalty: float = 0.0,
            restitution: float | None = None, thrust_noise: float = 0.0, initial_position_noise_m: float = 0.0,
            max_cycles: int | None = None, render_mode: str | None = None, render_width_px: int = 600,
            impact_velocity_noise_mps: float = 0.0, **unknown: Any):
    """The AEC form without the order-enforcing wrapper; the arguments of :class:`TransportParallelEnv`."""
    return parallel_to_aec_wrapper(parallel_env(scenario, reward_mode, fuel_penalty, restitution, thrust_noise,
                                                initial_position_noise_m, max_cycles, render_mode,
                                                render_width_px, impact_velocity_noise_mps, **unknown))


def env(scenario: Scenario | str = DEFAULT_SCENARIO, reward_mode: str = "dense", fuel_penalty: float = 0.0,
        restitution: float | None = None, thrust_noise: float = 0.0, initial_position_noise_m: float = 0.0,
        max_cycles: int | None = None, render_mode: str | None = None, render_width_px: int = 600,
        impact_velocity_noise_mps: float = 0.0, **unknown: Any):
    """The AEC form, order-enforced (what ``pettingzoo.test.api_test`` expects); the arguments of
    :class:`TransportParallelEnv`."""
    return OrderEnforcingWrapper(raw_env(scenario, reward_mode, fuel_penalty, restitution, thrust_noise,
                                         initial_position_noise_m, max_cycles, render_mode, render_width_px,
                                         impact_velocity_noise_mps, **unknown))
