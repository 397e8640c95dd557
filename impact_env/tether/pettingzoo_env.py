"""PettingZoo environment of tether transport: one agent per robot, a shared team reward.

Entry points follow PettingZoo's convention: :func:`parallel_env` (the ParallelEnv), :func:`raw_env` (its AEC
form without wrappers) and :func:`env` (the AEC form, order-enforced); ``*_v0`` build the version-0 env that
:mod:`impact_env.tether_v0` keeps for one release.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo.utils.conversions import parallel_to_aec_wrapper
from pettingzoo.utils.wrappers import OrderEnforcingWrapper

from impact_env.env_shell import ParallelShell, required
from impact_env.errors import ActionError, brief
from impact_env.tether.core import KEEP, TetherCore
from impact_env.tether.faults import FaultConfig
from impact_env.tether.gym_env import STATION_HINT
from impact_env.tether.rendering import TetherFrame, TetherRenderer, frame_of
from impact_env.tether.station import Station

# what the module-level entry points make without arguments (see impact_env.transport.pettingzoo_env)
DEFAULT_STATION = "L"


class TetherParallelEnv(ParallelShell):
    """Tether transport with one agent per robot, named by the station's robot names (``R1 .. Rn`` by default).

    ## Description
    The station, task and reward of :class:`~impact_env.tether.gym_env.TetherEnv` with each robot an agent of a
    PettingZoo ``ParallelEnv``; ``raw_env`` and ``env`` are its AEC forms. Import it as
    ``from impact_env import tether_v1`` or make it with PettingZoo's registry id ``impact_env/tether-v1``.

    ## Agents
    One per robot, in robot order, named as the station file's ``robots.names`` (``R1``, ``R2``, ... when it
    lists none, as the impact world's robots).

    ## Action space
    Per agent ``Discrete(n_anchors + 3)``: its own command (``0`` keep, ``1`` release, ``2 + j`` attach to
    anchor ``j``, ``n_anchors + 2`` hold; rules and errors as in ``TetherEnv``, robots served in order). A missing
    agent action, or None, means keep; an action for an agent the env does not have, or one that is not a single
    integer command, is an :class:`~impact_env.errors.ActionError`.

    ## Observation space
    Per agent the central layout of ``TetherEnv`` with the agent's own robot block first and the others after
    it in order, so one shared policy can drive every robot. ``state()`` returns the central observation.

    ## Rewards
    All agents receive the same team reward (``TetherEnv``'s).

    ## Episode end
    All agents terminate together at the task's horizon; ``max_cycles`` truncates earlier if given.

    ## Arguments
    * ``station``: a shipped station name, a path to a TOML file or a :class:`~impact_env.tether.station.Station`;
      required by the class; the module's ``parallel_env``, ``env`` and ``raw_env`` default to ``"L"``.
    * ``fidelity``: ``"kinematic"``, ``"reel"`` or ``"force"``.
    * ``reward_mode``: ``"dense"`` or ``"sparse"``.
    * ``energy_penalty``: reward cost per joule of winch work (>= 0).
    * ``pull_speed_mps``: the winches' real pulling speed; None keeps the station's.
    * ``max_active``: ``k``; None keeps the station's.
    * ``initial_position_noise_m``: the cargo starts uniformly within this radius (m) of its start.
    * ``max_cycles``: truncate after this many steps (None: only the horizon ends an episode).
    * ``render_mode``: ``"rgb_array"``, ``"human"`` or None.
    * ``render_width_px``: width of the rendered frame.
    * ``faults``: the episode's faults, a :class:`~impact_env.tether.faults.FaultConfig` or a dict of its fields;
      None: none.

    ## Metadata
    ``metadata["name"]`` is ``tether_<station>_v1`` (e.g. ``tether_L_v1``).

    ## Version history
    * v1: agents named by the station's robot names (``R1 .. Rn``; were ``robot_0 .. robot_{n-1}``), the task,
      hold command, observation, ``info`` and faults of ``TetherEnv`` v1; typed errors for actions of unknown
      agents and malformed actions. ``impact_env/tether-v0`` (:mod:`impact_env.tether_v0`) keeps version 0 for
      one release (removed in 0.4.0).
    * v0: initial release (impact_env 0.2.0).
    """

    metadata: dict[str, Any] = {"render_modes": ["human", "rgb_array"], "render_fps": 10, "name": "tether_v1",
                "is_parallelizable": True}
    version = 1

    def __init__(self, station: Station | str | None = None, fidelity: str = "kinematic", reward_mode: str = "dense",
                 energy_penalty: float = 0.0, pull_speed_mps: float | None = None, max_active: int | None = None,
                 initial_position_noise_m: float = 0.0, max_cycles: int | None = None,
                 render_mode: str | None = None, render_width_px: int = 600,
                 faults: FaultConfig | dict | None = None, **unknown: Any) -> None:
        self._open(unknown, (station, fidelity, reward_mode, energy_penalty, pull_speed_mps, max_active,
                             initial_position_noise_m, max_cycles, render_mode, render_width_px, faults),
                   render_mode, render_width_px, max_cycles)
        module = "tether_v1" if self.version == 1 else "tether_v0"
        station = required(station, "station", STATION_HINT, f"impact_env.{module}.parallel_env(station='L')")
        self.core = TetherCore(station, fidelity=fidelity, reward_mode=reward_mode, energy_penalty=energy_penalty,
                               pull_speed_mps=pull_speed_mps, max_active=max_active,
                               initial_position_noise_m=initial_position_noise_m, faults=faults,
                               version=self.version)
        self.station = self.core.station
        self.metadata = dict(self.metadata, name=f"tether_{self.station.name}_v{self.version}")
        self._set_agents(self.agent_names(self.station), spaces.Discrete(self.core.n_commands))

    @staticmethod
    def agent_names(station: Station) -> list[str]:
        """The agents of a station: its robots' names."""
        return list(station.robot_names)

    def _joint_action(self, actions: Any) -> list:
        if not isinstance(actions, dict):
            raise ActionError(f"actions must be a dict agent -> command, got {brief(actions)}")
        unknown = [a for a in actions if a not in self.action_spaces]
        if unknown:
            raise ActionError(f"actions for unknown agents {brief(unknown)}; agents are {self.possible_agents}")
        joint = []
        for agent in self.possible_agents:
            value = actions.get(agent)
            if value is None:
                joint.append(KEEP)
                continue
            if type(value) is int:
                joint.append(value)
                continue
            try:
                flat = np.asarray(value).reshape(-1)
            except (TypeError, ValueError) as exc:
                raise ActionError(f"the action of {agent} must be one integer command, got {brief(value)}") from exc
            if flat.size != 1:
                raise ActionError(f"the action of {agent} must be one integer command, got {brief(value)}")
            joint.append(flat[0].item() if flat.dtype.kind in "iufb" else flat[0])
        return joint

    def _observations(self) -> dict[str, np.ndarray]:
        core, agents = self.core, self.agents
        return {a: core.agent_observation(i) for i, a in enumerate(self.possible_agents) if a in agents}

    def _new_renderer(self, render_mode: str) -> TetherRenderer:
        return TetherRenderer(self.station, render_mode, width_px=self.render_width_px,
                              fps=self.metadata["render_fps"])

    def _frame(self) -> TetherFrame:
        return frame_of(self.core)


class TetherParallelEnvV0(TetherParallelEnv):
    """Version 0 of the PettingZoo tether environment (``impact_env/tether-v0``, :mod:`impact_env.tether_v0`),
    kept for one release (removed in 0.4.0): agents ``robot_0 .. robot_{n-1}``, and the task and spaces of
    :class:`~impact_env.tether.gym_env.TetherEnvV0`. Use :class:`TetherParallelEnv` (``-v1``).

    ## Arguments
    * ``station``: a shipped station name, a path to a TOML file or a :class:`~impact_env.tether.station.Station`;
      required by the class (the module's entry points make station L without one).
    * ``fidelity``: ``"kinematic"``, ``"reel"`` or ``"force"``.
    * ``reward_mode``: ``"dense"`` or ``"sparse"``.
    * ``energy_penalty``: reward cost per joule of winch work (>= 0).
    * ``pull_speed_mps``: the winches' real pulling speed; None keeps the station's.
    * ``max_active``: ``k``; None keeps the station's.
    * ``initial_position_noise_m``: the cargo starts uniformly within this radius (m) of its start.
    * ``max_cycles``: truncate after this many steps (None: only the horizon ends an episode).
    * ``render_mode``: ``"rgb_array"``, ``"human"`` or None.
    * ``render_width_px``: width of the rendered frame.
    * ``faults``: the episode's faults (see :class:`TetherParallelEnv`).

    ## Version history
    * v0: initial release (impact_env 0.2.0); superseded by v1 (:class:`TetherParallelEnv`).
    """

    metadata = dict(TetherParallelEnv.metadata, name="tether_v0")
    version = 0

    @staticmethod
    def agent_names(station: Station) -> list[str]:
        return [f"robot_{i}" for i in range(station.n_robots)]


def parallel_env(station: Station | str = DEFAULT_STATION, fidelity: str = "kinematic", reward_mode: str = "dense",
                 energy_penalty: float = 0.0, pull_speed_mps: float | None = None, max_active: int | None = None,
                 initial_position_noise_m: float = 0.0, max_cycles: int | None = None, render_mode: str | None = None,
                 render_width_px: int = 600, faults: FaultConfig | dict | None = None,
                 **unknown: Any) -> TetherParallelEnv:
    """The ParallelEnv; the arguments of :class:`TetherParallelEnv`."""
    return TetherParallelEnv(station, fidelity, reward_mode, energy_penalty, pull_speed_mps, max_active,
                             initial_position_noise_m, max_cycles, render_mode, render_width_px, faults, **unknown)


def raw_env(station: Station | str = DEFAULT_STATION, fidelity: str = "kinematic", reward_mode: str = "dense",
            energy_penalty: float = 0.0, pull_speed_mps: float | None = None, max_active: int | None = None,
            initial_position_noise_m: float = 0.0, max_cycles: int | None = None, render_mode: str | None = None,
            render_width_px: int = 600, faults: FaultConfig | dict | None = None, **unknown: Any):
    """The AEC form without the order-enforcing wrapper; the arguments of :class:`TetherParallelEnv`."""
    return parallel_to_aec_wrapper(parallel_env(station, fidelity, reward_mode, energy_penalty, pull_speed_mps,
                                                max_active, initial_position_noise_m, max_cycles, render_mode,
                                                render_width_px, faults, **unknown))


def env(station: Station | str = DEFAULT_STATION, fidelity: str = "kinematic", reward_mode: str = "dense",
        energy_penalty: float = 0.0, pull_speed_mps: float | None = None, max_active: int | None = None,
        initial_position_noise_m: float = 0.0, max_cycles: int | None = None, render_mode: str | None = None,
        render_width_px: int = 600, faults: FaultConfig | dict | None = None, **unknown: Any):
    """The AEC form, order-enforced (what ``pettingzoo.test.api_test`` expects); the arguments of
    :class:`TetherParallelEnv`."""
    return OrderEnforcingWrapper(raw_env(station, fidelity, reward_mode, energy_penalty, pull_speed_mps, max_active,
                                         initial_position_noise_m, max_cycles, render_mode, render_width_px, faults,
                                         **unknown))


def parallel_env_v0(station: Station | str = DEFAULT_STATION, fidelity: str = "kinematic",
                    reward_mode: str = "dense", energy_penalty: float = 0.0, pull_speed_mps: float | None = None,
                    max_active: int | None = None,
                    initial_position_noise_m: float = 0.0, max_cycles: int | None = None,
                    render_mode: str | None = None, render_width_px: int = 600,
                    faults: FaultConfig | dict | None = None, **unknown: Any) -> TetherParallelEnvV0:
    """Version 0's ParallelEnv; the arguments of :class:`TetherParallelEnvV0`."""
    return TetherParallelEnvV0(station, fidelity, reward_mode, energy_penalty, pull_speed_mps, max_active,
                               initial_position_noise_m, max_cycles, render_mode, render_width_px, faults, **unknown)


def raw_env_v0(station: Station | str = DEFAULT_STATION, fidelity: str = "kinematic", reward_mode: str = "dense",
               energy_penalty: float = 0.0, pull_speed_mps: float | None = None, max_active: int | None = None,
               initial_position_noise_m: float = 0.0, max_cycles: int | None = None, render_mode: str | None = None,
               render_width_px: int = 600, faults: FaultConfig | dict | None = None, **unknown: Any):
    """Version 0's AEC form without the order-enforcing wrapper."""
    return parallel_to_aec_wrapper(parallel_env_v0(station, fidelity, reward_mode, energy_penalty, pull_speed_mps,
                                                   max_active, initial_position_noise_m, max_cycles, render_mode,
                                                   render_width_px, faults, **unknown))


def env_v0(station: Station | str = DEFAULT_STATION, fidelity: str = "kinematic", reward_mode: str = "dense",
           energy_penalty: float = 0.0, pull_speed_mps: float | None = None, max_active: int | None = None,
           initial_position_noise_m: float = 0.0, max_cycles: int | None = None, render_mode: str | None = None,
           render_width_px: int = 600, faults: FaultConfig | dict | None = None, **unknown: Any):
    """Version 0's AEC form, order-enforced."""
    return OrderEnforcingWrapper(raw_env_v0(station, fidelity, reward_mode, energy_penalty, pull_speed_mps,
                                            max_active, initial_position_noise_m, max_cycles, render_mode,
                                            render_width_px, faults, **unknown))
