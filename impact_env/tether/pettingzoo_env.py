"""PettingZoo environment of tether transport: one agent per robot, a shared team reward.

Entry points follow PettingZoo's convention: :func:`parallel_env` (the ParallelEnv), :func:`raw_env` (its AEC
form without wrappers) and :func:`env` (the AEC form, order-enforced).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo.utils.conversions import parallel_to_aec_wrapper
from pettingzoo.utils.wrappers import OrderEnforcingWrapper

from impact_env.env_shell import ParallelShell, required
from impact_env.tether.core import KEEP, TetherCore
from impact_env.tether.gym_env import STATION_HINT
from impact_env.tether.rendering import TetherFrame, TetherRenderer, frame_of
from impact_env.tether.station import Station

# what the module-level entry points make without arguments (see impact_env.transport.pettingzoo_env)
DEFAULT_STATION = "L"


class TetherParallelEnv(ParallelShell):
    """Tether transport with one agent per robot (agents ``robot_0 .. robot_{n-1}``).

    ## Description
    The station, task and reward of :class:`~impact_env.tether.gym_env.TetherEnv` with each robot an agent of a
    PettingZoo ``ParallelEnv``; ``raw_env`` and ``env`` are its AEC forms. Import it as
    ``from impact_env import tether_v0`` or make it with PettingZoo's registry id ``impact_env/tether-v0``.

    ## Action space
    Per agent ``Discrete(n_anchors + 2)``: its own command (``0`` keep, ``1`` release, ``2 + j`` attach to
    anchor ``j``; rules and errors as in ``TetherEnv``, robots served in index order). A missing agent action
    means keep.

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

    ## Metadata
    ``metadata["name"]`` is ``tether_<station>_v0`` (e.g. ``tether_L_v0``).

    ## Version history
    * v0: initial release (impact_env 0.2.0).
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 10, "name": "tether_v0",
                "is_parallelizable": True}

    def __init__(self, station: Station | str | None = None, fidelity: str = "kinematic", reward_mode: str = "dense",
                 energy_penalty: float = 0.0, pull_speed_mps: float | None = None, max_active: int | None = None,
                 initial_position_noise_m: float = 0.0, max_cycles: int | None = None,
                 render_mode: str | None = None, render_width_px: int = 600, **unknown: Any) -> None:
        self._open(unknown, (station, fidelity, reward_mode, energy_penalty, pull_speed_mps, max_active,
                             initial_position_noise_m, max_cycles, render_mode, render_width_px),
                   render_mode, render_width_px, max_cycles)
        station = required(station, "station", STATION_HINT, "impact_env.tether_v0.parallel_env(station='L')")
        self.core = TetherCore(station, fidelity=fidelity, reward_mode=reward_mode, energy_penalty=energy_penalty,
                               pull_speed_mps=pull_speed_mps, max_active=max_active,
                               initial_position_noise_m=initial_position_noise_m)
        self.station = self.core.station
        self.metadata = dict(self.metadata, name=f"tether_{self.station.name}_v0")
        self._set_agents([f"robot_{i}" for i in range(self.core.n_robots)], spaces.Discrete(self.core.n_commands))

    def _joint_action(self, actions: dict[str, Any]) -> list:
        unknown = set(actions) - set(self.possible_agents)
        if unknown:
            raise KeyError(f"actions for unknown agents {sorted(unknown)}; agents are {self.possible_agents}")
        return [KEEP if actions.get(a) is None else np.asarray(actions[a]).reshape(-1)[0] for a in self.possible_agents]

    def _new_renderer(self) -> TetherRenderer:
        return TetherRenderer(self.station, self.render_mode, width_px=self.render_width_px,
                              fps=self.metadata["render_fps"])

    def _frame(self) -> TetherFrame:
        return frame_of(self.core)


def parallel_env(station: Station | str = DEFAULT_STATION, fidelity: str = "kinematic", reward_mode: str = "dense",
                 energy_penalty: float = 0.0, pull_speed_mps: float | None = None, max_active: int | None = None,
                 initial_position_noise_m: float = 0.0, max_cycles: int | None = None, render_mode: str | None = None,
                 render_width_px: int = 600, **unknown: Any) -> TetherParallelEnv:
    """The ParallelEnv; the arguments of :class:`TetherParallelEnv`."""
    return TetherParallelEnv(station, fidelity, reward_mode, energy_penalty, pull_speed_mps, max_active,
                             initial_position_noise_m, max_cycles, render_mode, render_width_px, **unknown)


def raw_env(station: Station | str = DEFAULT_STATION, fidelity: str = "kinematic", reward_mode: str = "dense",
            energy_penalty: float = 0.0, pull_speed_mps: float | None = None, max_active: int | None = None,
            initial_position_noise_m: float = 0.0, max_cycles: int | None = None, render_mode: str | None = None,
            render_width_px: int = 600, **unknown: Any):
    """The AEC form without the order-enforcing wrapper; the arguments of :class:`TetherParallelEnv`."""
    return parallel_to_aec_wrapper(parallel_env(station, fidelity, reward_mode, energy_penalty, pull_speed_mps,
                                                max_active, initial_position_noise_m, max_cycles, render_mode,
                                                render_width_px, **unknown))


def env(station: Station | str = DEFAULT_STATION, fidelity: str = "kinematic", reward_mode: str = "dense",
        energy_penalty: float = 0.0, pull_speed_mps: float | None = None, max_active: int | None = None,
        initial_position_noise_m: float = 0.0, max_cycles: int | None = None, render_mode: str | None = None,
        render_width_px: int = 600, **unknown: Any):
    """The AEC form, order-enforced (what ``pettingzoo.test.api_test`` expects); the arguments of
    :class:`TetherParallelEnv`."""
    return OrderEnforcingWrapper(raw_env(station, fidelity, reward_mode, energy_penalty, pull_speed_mps, max_active,
                                         initial_position_noise_m, max_cycles, render_mode, render_width_px, **unknown))
