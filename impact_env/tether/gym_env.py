"""Gymnasium environment of anchor-pull (tether) transport: robots pull the cargo toward wall anchors."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from impact_env.env_shell import GymShell, required, with_horizon
from impact_env.tether.core import TetherCore
from impact_env.tether.faults import FaultConfig
from impact_env.tether.rendering import TetherFrame, TetherRenderer, frame_of
from impact_env.tether.station import Station

STATION_HINT = "a shipped station name (impact-env scenarios), a path to a TOML file or a Station"
STATION_EXAMPLE = ("gym.make('impact_env/Tether-v1', station='L'), or the station's own id "
                   "gym.make('impact_env/TetherL-v1')")


class TetherEnv(GymShell):
    """Robots carry a free-floating cargo through a space station by pulling it toward anchors on the walls,
    deliver it into the goal box and hold it there at rest.

    ## Description
    A station (``impact_env/tether/stations/*.toml`` or your own file, see ``docs/station_format.md``) is a polygon
    with anchor points on its walls, a cargo disc, a goal box and a fleet of robots. A robot attaches a tether to
    the cargo and to an anchor and reels it in: with one tether the cargo moves straight toward the anchor at the
    pulling speed ``w``, with several along the sum of their directions (the thesis's Eq. 5). A robot's winch can
    also hold its tether at its length (a brake): it stops a cargo moving away from the anchor. At most ``k``
    robots hold anchors at once, each on a distinct anchor. A tether needs line of sight: when a wall comes
    between cargo and anchor it snags (is released), and it is released when the cargo comes within the stop
    radius of its anchor. How the cargo moves depends on ``fidelity`` (``kinematic``: exactly Eq. 5, no
    inertia; ``reel``: pymunk slide joints reeled in at ``w`` with the winch force limit, the cargo keeps its
    momentum; ``force``: saturating winch tension), see :mod:`impact_env.tether.physics`. Anchors can fail,
    tethers snap, robots drop out and winches run off their speed (``faults``).

    ## Action space
    ``MultiDiscrete([n_anchors + 3] * n_robots)``: per robot, ``0`` keep, ``1`` release, ``2 + j`` attach to
    anchor ``j`` (``station.anchors[j]``), ``n_anchors + 2`` hold (the winch stops reeling and brakes; attaching
    again to the anchor it holds reels in again). Attaching takes ``t_switch`` (the station's ``switch_time_s``)
    before the tether pulls. Attaches that break a rule (anchor not in line of sight, inside its stop radius, held
    by another robot, ``k`` other robots already holding anchors, the robot dropped out) and holds without a
    tether are ignored and reported in ``info["rejected"]``; commands outside ``0 .. n_anchors + 2``,
    non-integers, NaN or the wrong count raise :class:`~impact_env.errors.ActionError`. Robots are served in
    order within a step.

    ## Observation space
    ``Box(float32)`` of size ``4 + n_robots * (n_anchors + 3) + n_anchors + 1``, fixed per station:
    cargo ``x, y`` (m, within the station's bounding box) and ``vx, vy`` (m/s, within ``+- v_max``: ``k w``
    under ``kinematic``; an energy bound under ``reel`` and ``force``); then per robot a one-hot of the anchor it
    holds (all zeros for none), the fraction of ``t_switch`` left before its tether pulls (0 when pulling or
    free), the tether length (m, cargo centre to anchor, 0 for none) and 1 if its winch holds; then the
    line-of-sight mask of the anchors from the cargo centre (1 visible); last, the fraction of the episode's time
    left.

    ## Rewards
    The spatial robustness (m) of the station's STL task, by default "deliver and hold":
    ``F[0,tf - hold] G[0,hold] (in(cargo, goal) & in(drift, rest))``, reach the goal box and stay in it at rest
    (slower than the station's ``rest_speed_mps``) for its ``hold_s`` (30 s on the shipped maps); ``drift`` is
    the velocity times ``hold_s`` (m), so both parts are in metres. ``reward_mode="dense"`` (default): the
    per-step increment of the online robustness estimate, so an episode's rewards sum to its final robustness;
    ``"sparse"``: the final robustness on the last step. Both subtract ``energy_penalty`` times the step's winch
    work (J).

    ## Starting state
    The cargo at rest at the station's start, no tethers. With ``initial_position_noise_m > 0`` the cargo starts
    uniformly within that radius of the start (drawn from the reset seed, the disc kept inside the station); the
    faults are drawn from the reset seed after it.

    ## Episode end
    ``terminated`` when the task's horizon is reached (``env.unwrapped.horizon_steps``: 600 steps of 1 s on the
    shipped maps); the final ``info["robustness"]`` is then the trace's exact robustness and
    ``info["is_success"]`` says whether it is positive. As for the impact envs, the station ids are registered
    with ``max_episode_steps`` equal to the horizon (``TimeLimit`` also sets ``truncated`` on that last step;
    ``terminated`` is the authoritative signal); ``impact_env/Tether-v1`` reads it from the station given to
    ``make`` (:func:`make_with_horizon`).

    ## Info
    ``robustness`` (m), ``is_success``, ``time_s``, ``switches`` (accepted attach commands), ``snags``,
    ``path_length_m`` (of the cargo centre), ``winch_work_J``, ``wall_contacts`` (all cumulative); ``speed_mps``
    (the cargo's, now: the final speed at the end), ``time_to_goal_s`` (when the cargo centre first entered the
    goal box, None before), ``time_in_goal_s`` (how long it has been in the box without leaving) and
    ``time_at_rest_in_goal_s`` (how long it has been in the box at rest: the hold so far); ``failed_anchors`` and
    ``dropped_robots`` (those that showed their fault so far); ``events`` (this step's tether events: dicts with
    ``time``, ``kind`` in attached / released / arrived / snagged / blocked / refused / anchor_failed / snapped /
    dropped_out, ``robot``, ``anchor``) and ``rejected`` (this step's ignored commands with the reason).

    ## Arguments
    Each keyword has the name of its ``impact-env run`` option (``energy_penalty`` is ``--energy-penalty``).

    * ``station``: a shipped station name (``impact-env scenarios``), a path to a TOML file or a
      :class:`~impact_env.tether.station.Station`. Required by ``impact_env/Tether-v1``; the station ids
      (``impact_env/TetherL-v1`` ...) set it.
    * ``fidelity``: ``"kinematic"`` (the thesis's Eq. 5), ``"reel"`` (slide joints reeled in) or ``"force"``
      (saturating tension).
    * ``reward_mode``: ``"dense"`` or ``"sparse"``.
    * ``energy_penalty``: reward cost per joule of winch work (>= 0).
    * ``pull_speed_mps``: the winches' real pulling speed ``w``; None keeps the station's.
    * ``max_active``: ``k``, how many robots may hold anchors at once; None keeps the station's.
    * ``initial_position_noise_m``: the cargo starts uniformly within this radius (m) of its start.
    * ``render_mode``: ``"rgb_array"``, ``"human"`` or None.
    * ``render_width_px``: width of the rendered frame.
    * ``faults``: the episode's faults, a :class:`~impact_env.tether.faults.FaultConfig` or a dict of its fields
      (``anchor_failures``, ``tether_snaps``, ``robot_dropouts``, ``winch_speed_error``, ``window_s``), drawn from
      the reset seed; None: none.

    ## Version history
    * v1: the default task is "deliver and hold" (was "eventually in the goal"); the hold command and the
      holding flag in the observation; ``info`` reports the speed and the times in the goal; faults; winch work at
      kinematic fidelity from Eq. 5's tension (was the kinetic energy given to the cargo). The ``-v0`` ids
      (``impact_env/TetherL-v0`` ..., :class:`TetherEnvV0`) keep the old task, action and observation spaces for
      one release (removed in 0.4.0).
    * v0: initial release (impact_env 0.2.0).
    """

    metadata: dict[str, Any] = {"render_modes": ["human", "rgb_array"], "render_fps": 10}
    version = 1

    def __init__(self, station: Station | str | None = None, fidelity: str = "kinematic", reward_mode: str = "dense",
                 energy_penalty: float = 0.0, pull_speed_mps: float | None = None, max_active: int | None = None,
                 initial_position_noise_m: float = 0.0, render_mode: str | None = None,
                 render_width_px: int = 600, faults: FaultConfig | dict | None = None, **unknown: Any) -> None:
        self._open(unknown, (station, fidelity, reward_mode, energy_penalty, pull_speed_mps, max_active,
                             initial_position_noise_m, render_mode, render_width_px, faults), render_mode,
                   render_width_px)
        station = required(station, "station", STATION_HINT, STATION_EXAMPLE)
        self.core = TetherCore(station, fidelity=fidelity, reward_mode=reward_mode, energy_penalty=energy_penalty,
                               pull_speed_mps=pull_speed_mps, max_active=max_active,
                               initial_position_noise_m=initial_position_noise_m, faults=faults,
                               version=self.version)
        self.station = self.core.station
        self.action_space = spaces.MultiDiscrete([self.core.n_commands] * self.core.n_robots)
        self.observation_space = spaces.Box(self.core.obs_low, self.core.obs_high, dtype=np.float32)

    def _new_renderer(self, render_mode: str) -> TetherRenderer:
        return TetherRenderer(self.station, render_mode, width_px=self.render_width_px,
                              fps=self.metadata["render_fps"])

    def _frame(self) -> TetherFrame:
        return frame_of(self.core)


class TetherEnvV0(TetherEnv):
    """The tether environment as it was in version 0 (``impact_env/TetherL-v0`` ..., ``impact_env/Tether-v0``),
    kept for one release (removed in 0.4.0): use :class:`TetherEnv` (``-v1``).

    ## Description
    :class:`TetherEnv` with the version-0 task and spaces: a station whose task is its default flies
    ``F[0,tf] in(cargo, goal)`` ("eventually in the goal", the cargo need not stay); no hold command
    (``MultiDiscrete([n_anchors + 2] * n_robots)``) and no holding flag in the observation (robot blocks of
    ``n_anchors + 2``). Faults, the new ``info`` entries and the winch work are those of version 1.

    ## Arguments
    * ``station``: a shipped station name, a path to a TOML file or a :class:`~impact_env.tether.station.Station`.
    * ``fidelity``: ``"kinematic"``, ``"reel"`` or ``"force"``.
    * ``reward_mode``: ``"dense"`` or ``"sparse"``.
    * ``energy_penalty``: reward cost per joule of winch work (>= 0).
    * ``pull_speed_mps``: the winches' real pulling speed ``w``; None keeps the station's.
    * ``max_active``: ``k``; None keeps the station's.
    * ``initial_position_noise_m``: the cargo starts uniformly within this radius (m) of its start.
    * ``render_mode``: ``"rgb_array"``, ``"human"`` or None.
    * ``render_width_px``: width of the rendered frame.
    * ``faults``: the episode's faults (see :class:`TetherEnv`).

    ## Version history
    * v0: initial release (impact_env 0.2.0); superseded by v1 (:class:`TetherEnv`).
    """

    version = 0


# impact_env.tether.gym_env's names (0.2), kept for that old path's release
def render_tether(env: GymShell) -> Any:
    """``env.render()``'s drawing."""
    return env._draw()


def close_tether(env: GymShell) -> None:
    env.close()


def make_with_horizon(**kwargs: Any) -> gym.Env:
    """The entry point of ``impact_env/Tether-v1``: ``TetherEnv(**kwargs)`` in Gymnasium's ``TimeLimit`` at its
    station's horizon (:func:`~impact_env.env_shell.with_horizon`)."""
    return with_horizon(TetherEnv(**kwargs))


def make_v0_with_horizon(**kwargs: Any) -> gym.Env:
    """The entry point of ``impact_env/Tether-v0``: :class:`TetherEnvV0` at its station's horizon."""
    return with_horizon(TetherEnvV0(**kwargs))
