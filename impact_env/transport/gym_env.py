"""Gymnasium environment: central control of all robots of a transport scenario."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from impact_env.env_shell import GymShell, required, with_horizon
from impact_env.transport.core import ACTION_PER_ROBOT, TransportCore
from impact_env.transport.rendering import Renderer, RenderFrame, frame_of
from impact_env.transport.scenario import Scenario

SCENARIO_HINT = "a shipped scenario name (impact-env scenarios), a path to a TOML file or a Scenario"
SCENARIO_EXAMPLE = ("gym.make('impact_env/Transport-v0', scenario='corridor'), or the scenario's own id "
                    "gym.make('impact_env/Corridor-v0')")


class TransportEnv(GymShell):
    """Robots move passive free-floating objects by impacts, in a 2D frictionless microgravity world.

    ## Description
    A scenario (``impact_env/transport/scenarios/*.toml`` or your own file) places robots and objects (discs) in a
    box with solid obstacles. Robots are actuated free-flyers; objects move only when hit. Restitution is
    the scenario's ``e`` for every contact. The task is an STL formula over the bodies' positions; the
    reward is its spatial robustness (metres).

    ## Action space
    ``Box(-1, 1, (3 * n_robots,), float32)``: per robot, in scenario order, body-frame force x, force y
    and torque, as fractions of the robot's ``thrust_limit_N`` (per body axis) and ``torque_limit_Nm``.
    Values outside [-1, 1] are clipped; NaN or infinite values raise
    :class:`~impact_env.errors.ActionError`, and so do non-numbers, ragged lists and any shape other than
    ``(3 * n_robots,)`` or ``(n_robots, 3)``. The wrench is held for one control period
    (``control_period_s``, 0.1 s by default) of several physics substeps.

    ## Observation space
    ``Box(float32)`` of size ``7 * n_bodies + 1``: for each body (robots, then objects, scenario order)
    ``x, y`` (m, within the world box), ``vx, vy`` (m/s), ``cos(heading), sin(heading)`` and angular
    velocity (rad/s); last, the fraction of the episode's time left (1 at reset, 0 at the end).

    ## Rewards
    ``reward_mode="dense"`` (default): the per-step increment of the online STL robustness estimate
    (the trace so far with its last sample held), so an episode's rewards sum to its final robustness.
    ``reward_mode="sparse"``: the final robustness on the last step, 0 before.
    ``reward_mode="conjuncts"``: the per-step increment of the mean robustness of the task's conjuncts, so
    each conjunct (e.g. each wall clearance) is credited when it changes (see impact_env.transport.core). All subtract
    ``fuel_penalty * sum_robots |F| * dt`` (N s) if ``fuel_penalty > 0``. A robustness of +-inf (a task that
    holds or fails whatever happens, e.g. ``F[0,20] true``) is reported clipped to +- the diagonal of the box
    around the world and every region, so rewards stay finite.

    ## Starting state
    The scenario's initial positions, velocities and headings. With ``initial_position_noise_m > 0``,
    objects start uniformly within that radius of their scenario position (drawn from the reset seed); a
    draw whose disc would leave the world, overlap an obstacle or another body is drawn again from the same
    generator, and a radius for which fewer than 5 % of the draws are clear is refused at construction.

    ## Episode end
    ``terminated`` when the STL formula's horizon is reached (``env.unwrapped.horizon_steps`` steps of
    ``env.unwrapped.dt_s``: 1000 steps of 0.1 s for the corridor); the final ``info["robustness"]`` is then the
    trace's exact robustness and ``info["is_success"]`` says whether it is positive. The horizon is part of the
    task and the time left is in the observation, so this is a true termination (do not bootstrap).

    ``gym.make`` registers each shipped scenario with ``max_episode_steps`` equal to its horizon, so
    ``env.spec.max_episode_steps`` tells the episode length; on the last step Gymnasium's ``TimeLimit`` then
    also sets ``truncated=True``. Read ``terminated`` as the authoritative signal (stable-baselines3 does:
    its ``TimeLimit.truncated`` is ``truncated and not terminated``). A smaller ``max_episode_steps`` passed to
    ``gym.make`` cuts episodes short with ``truncated`` only. ``impact_env/Transport-v0`` reads the horizon from
    the scenario given to ``make`` (:func:`make_with_horizon`), so its ``env.spec.max_episode_steps`` is the
    file's too.

    ## Info
    ``robustness`` (current estimate, m), ``is_success`` (robustness > 0), ``impacts`` (contacts that ended
    during this step: dicts with ``time``, ``a``, ``b``, ``impulse`` and velocities before/after),
    ``fuel_Ns`` (cumulative), ``time_s``.

    ## Arguments
    Each keyword has the name of its ``impact-env run``/``train`` option (``reward_mode`` is
    ``--reward-mode``).

    * ``scenario``: a shipped name (``impact-env scenarios``), a path to a TOML file or a
      :class:`~impact_env.transport.scenario.Scenario`. Required by ``impact_env/Transport-v0``; the scenario ids
      (``impact_env/Corridor-v0`` ...) set it.
    * ``reward_mode``: ``"dense"``, ``"sparse"`` or ``"conjuncts"`` (see Rewards).
    * ``fuel_penalty``: reward cost per N s of fuel (>= 0).
    * ``restitution``: simulate with this restitution instead of the scenario's ``e`` (a model mismatch for the
      planner); None keeps the scenario's.
    * ``thrust_noise``: standard deviation of multiplicative thrust noise (0.05 = 5 %), re-clipped to the limits
      (at most 10).
    * ``initial_position_noise_m``: objects start uniformly within this radius (m) of their scenario position.
    * ``render_mode``: ``"rgb_array"`` (an ``(H, W, 3)`` uint8 frame per ``render()``), ``"human"`` (a pygame
      window) or None.
    * ``render_width_px``: width of the rendered frame; the height follows the world's aspect ratio.
    * ``impact_velocity_noise_mps``: after each robot-object impact, a uniform error in [-this, this] m/s per axis
      on the object's velocity, drawn from the reset seed (at most 1; 0, the default, leaves the dynamics as
      they were, so the version stays v0). The error an impact-robust plan's delta tolerates.

    ## Version history
    * v0: initial release (impact_env 0.1.0). In 0.3.0 ``impact_env/Transport-v0`` got the
      ``max_episode_steps`` of the scenario it is made with, and the scenarios relay, two_objects, ping_pong_stop
      and long_throw_trim their ids (``impact_env/Relay-v0`` ...); no episode changes. In 0.2.0 the ids got
      ``max_episode_steps``, ``scenario`` became
      required and the episode clock (``dt_s``, ``horizon_steps``, ``horizon_s``) moved onto the env; dynamics,
      reward and observations are unchanged, so the version stays v0. Also without a new version, because no
      episode that was valid before changes: malformed actions and options are refused, noisy starts that
      overlapped a wall, an obstacle or a body are drawn again, and an infinite robustness is clipped.
    """

    metadata: dict[str, Any] = {"render_modes": ["human", "rgb_array"], "render_fps": 10}

    def __init__(self, scenario: Scenario | str | None = None, reward_mode: str = "dense",
                 fuel_penalty: float = 0.0, restitution: float | None = None, thrust_noise: float = 0.0,
                 initial_position_noise_m: float = 0.0, render_mode: str | None = None,
                 render_width_px: int = 600, impact_velocity_noise_mps: float = 0.0, **unknown: Any) -> None:
        self._open(unknown, (scenario, reward_mode, fuel_penalty, restitution, thrust_noise, initial_position_noise_m,
                             render_mode, render_width_px, impact_velocity_noise_mps), render_mode, render_width_px)
        scenario = required(scenario, "scenario", SCENARIO_HINT, SCENARIO_EXAMPLE)
        self.core = TransportCore(scenario, reward_mode=reward_mode, fuel_penalty=fuel_penalty,
                                  restitution=restitution, thrust_noise=thrust_noise,
                                  initial_position_noise_m=initial_position_noise_m,
                                  impact_velocity_noise_mps=impact_velocity_noise_mps)
        self.scenario = self.core.scenario
        self.metadata = dict(self.metadata, render_fps=round(1.0 / self.scenario.control_period_s))
        n = self.core.n_robots * ACTION_PER_ROBOT
        self.action_space = spaces.Box(-1.0, 1.0, shape=(n,), dtype=np.float32)
        self.observation_space = spaces.Box(self.core.obs_low, self.core.obs_high, dtype=np.float32)

    def _new_renderer(self, render_mode: str) -> Renderer:
        return Renderer(self.scenario, render_mode, width_px=self.render_width_px, fps=self.metadata["render_fps"])

    def _frame(self) -> RenderFrame:
        return frame_of(self.core)


def make_with_horizon(**kwargs: Any) -> gym.Env:
    """The entry point of ``impact_env/Transport-v0``: ``TransportEnv(**kwargs)`` in Gymnasium's ``TimeLimit`` at
    its scenario's horizon (:func:`~impact_env.env_shell.with_horizon`)."""
    return with_horizon(TransportEnv(**kwargs))
