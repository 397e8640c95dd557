"""The shell of every environment: the Gymnasium and PettingZoo plumbing around a world family's core.

Each family (``impact_env.transport``, ``impact_env.tether``) has a core that owns the world, the STL monitor
and the episode's bookkeeping (``reset(rng)``, ``step(action) -> (reward, terminated, info)``, ``observation()``).
Its Gymnasium and PettingZoo classes translate that core into their APIs, and that translation is the same
for both families: :class:`GymShell` and :class:`ParallelShell` hold it, with the keyword checks (an unknown
keyword is a typed error naming the right one), the render options and the episode's clock (``dt_s``,
``horizon_steps``, ``horizon_s``; a Gymnasium wrapper does not forward attributes, so read them as
``env.unwrapped.dt_s``). A family's class adds its spaces, its docstring (the environment's page) and two
rendering hooks, ``_new_renderer()`` and ``_frame()``.
"""

from __future__ import annotations

import inspect
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.utils import EzPickle, seeding
from pettingzoo import ParallelEnv

from impact_env.catalogue import suggestion
from impact_env.errors import EnvConfigError, ImpactEnvError

# keywords users reach for that have another name here (the CLI's old option names among them)
_OTHER_NAMES = {"reward": "reward_mode", "init_noise": "initial_position_noise_m",
                "initial_noise": "initial_position_noise_m", "position_noise": "initial_position_noise_m",
                "e": "restitution", "map": "station", "scenario_name": "scenario"}


class EpisodeClock:
    """Mixin: the episode's control period and horizon, read from ``self.core``."""

    core: Any

    @property
    def dt_s(self) -> float:
        """Simulated time per step (s): the scenario's or station's ``control_period_s``."""
        return self.core.dt_s

    @property
    def horizon_steps(self) -> int:
        """Steps per episode: the task's horizon, where ``terminated`` becomes True."""
        return self.core.horizon_steps

    @property
    def horizon_s(self) -> float:
        """Simulated length of an episode (s): ``horizon_steps * dt_s``."""
        return self.core.horizon_steps * self.core.dt_s


# ------------------------------------------------------------------------------------------------ checks


def required(value: Any, name: str, what: str, example: str) -> Any:
    """``value`` unless it is None: an environment without its scenario or station is an error, not a default."""
    if value is None:
        raise EnvConfigError(f"{name}= is required: {what}; e.g. {example}")
    return value


def check_render_options(metadata: dict, render_mode: str | None, render_width_px: int) -> None:
    if render_mode is not None and render_mode not in metadata["render_modes"]:
        raise EnvConfigError(f"render_mode must be one of {metadata['render_modes']} or None, got {render_mode!r}")
    if not (type(render_width_px) is int and 16 <= render_width_px <= 8192):
        raise EnvConfigError(f"render_width_px must be an integer in 16..8192, got {render_width_px!r}")


def check_max_cycles(max_cycles: int | None) -> None:
    if max_cycles is not None and not (type(max_cycles) is int and max_cycles >= 1):
        raise EnvConfigError(f"max_cycles must be a positive integer or None, got {max_cycles!r}")


def reject_unknown(unknown: dict[str, Any], cls: type) -> None:
    """An unknown keyword is a typed error naming the right one (``reward=`` -> ``reward_mode``), not a default."""
    if not unknown:
        return
    # the class's own constructor, read (not called): mypy's warning is about calling it on an instance
    names = [p.name for p in inspect.signature(cls.__init__).parameters.values()  # type: ignore[misc]
             if p.name != "self" and p.kind is not p.VAR_KEYWORD]
    parts = []
    for key in unknown:
        hint = f" (did you mean {_OTHER_NAMES[key]!r}?)" if _OTHER_NAMES.get(key) in names else \
            suggestion(key, names, cutoff=0.5)
        parts.append(f"{key!r}{hint}")
    raise EnvConfigError(f"{cls.__name__} has no argument {', '.join(parts)}; its arguments are {', '.join(names)}")


def check_can_step(core: Any) -> None:
    """A core steps only between ``reset()`` and the task's horizon."""
    if core.world is None:
        raise ImpactEnvError("call reset() before step()")
    if core.step_count >= core.horizon_steps:
        raise ImpactEnvError("the episode has ended (the task's horizon was reached); call reset()")


def time_left(core: Any) -> float:
    """The observation's last entry: the fraction of the episode's steps still to come (1 at reset, 0 at the end)."""
    return max(0.0, 1.0 - core.step_count / core.horizon_steps)


def clip_to_space(obs: np.ndarray, core: Any) -> np.ndarray:
    """``obs`` (float32) clipped in place to the core's observation bounds, so it always lies in the space."""
    np.minimum(obs, core.obs_high, out=obs)
    return np.maximum(obs, core.obs_low, out=obs)


def with_horizon(env: GymShell) -> gym.Env:
    """``env`` in Gymnasium's ``TimeLimit`` at its task's horizon (``env.horizon_steps``).

    The entry point of the ids whose scenario or station is a ``gym.make`` argument (``impact_env/Transport-v0``,
    ``impact_env/Tether-v0``): their registration cannot know the horizon, so the env built from the file sets
    it, and ``env.spec.max_episode_steps`` is then the file's, as for the ids of shipped files. Gymnasium's
    ``make`` allows this: it records its spec on the unwrapped env and reads ``max_episode_steps`` back through
    this wrapper, and a ``max_episode_steps=`` given to ``make`` adds its own, outer ``TimeLimit``, which cuts
    earlier when it is smaller.
    """
    return gym.wrappers.TimeLimit(env, env.horizon_steps)


# ------------------------------------------------------------------------------------------------ shells


class _Rendered:
    """``render()``'s drawing and ``close()``: a renderer built on first use, a frame of the core per call."""

    core: Any
    render_mode: str | None
    render_width_px: int
    _renderer: Any = None

    def _new_renderer(self, render_mode: str) -> Any:  # the family's renderer of this env's scenario or station
        raise NotImplementedError

    def _frame(self) -> Any:  # what the renderer draws: the core's current state
        raise NotImplementedError

    def _draw(self) -> Any:
        if self._renderer is None:
            if self.render_mode is None:  # render() returns None first; the 0.2 paths' render(env) come here
                raise EnvConfigError("render_mode must be 'human' or 'rgb_array' to draw, got None")
            self._renderer = self._new_renderer(self.render_mode)
        return self._renderer.render(self._frame())

    def close(self) -> None:
        """Release the renderer (and its window in human mode)."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


class GymShell(_Rendered, EpisodeClock, gym.Env, EzPickle):
    """``reset``, ``step``, ``render`` and ``close`` of a Gymnasium environment around ``self.core``."""

    def _open(self, unknown: dict[str, Any], arguments: Sequence[Any], render_mode: str | None,
              render_width_px: int) -> None:
        """The start of every ``__init__``: unknown keywords refused, the arguments kept for pickling, the
        render options checked and set."""
        reject_unknown(unknown, type(self))
        EzPickle.__init__(self, *arguments)
        check_render_options(self.metadata, render_mode, render_width_px)
        self.render_mode = render_mode
        self.render_width_px = render_width_px
        self._renderer = None

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        self.core.reset(self.np_random)
        if self.render_mode == "human":
            self.render()
        return self.core.observation(), self.core.reset_info()

    def step(self, action):
        reward, terminated, info = self.core.step(action)
        if self.render_mode == "human":
            self.render()
        return self.core.observation(), reward, terminated, False, info

    def render(self):
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; pass render_mode='rgb_array' or 'human'")
            return None
        if self.core.world is None:
            raise gym.error.ResetNeeded("call reset() before render()")
        return self._draw()


class ParallelShell(_Rendered, EpisodeClock, ParallelEnv, EzPickle):
    """A PettingZoo ``ParallelEnv`` around ``self.core``: one agent per robot, a shared team reward.

    All agents terminate together at the task's horizon; ``max_cycles`` truncates earlier if given. A family's
    class turns the agents' actions into the core's joint action (``_joint_action``).
    """

    def _open(self, unknown: dict[str, Any], arguments: Sequence[Any], render_mode: str | None,
              render_width_px: int, max_cycles: int | None) -> None:
        """The start of every ``__init__``: as :meth:`GymShell._open`, and ``max_cycles`` checked and set."""
        reject_unknown(unknown, type(self))
        EzPickle.__init__(self, *arguments)
        check_render_options(self.metadata, render_mode, render_width_px)
        check_max_cycles(max_cycles)
        self.max_cycles = max_cycles
        self.render_mode = render_mode
        self.render_width_px = render_width_px
        self._renderer = None

    def _set_agents(self, agents: list[str], action_space: spaces.Space) -> None:
        """The agents, each with the core's observation space and ``action_space``; the central state space."""
        self.possible_agents = agents
        self.agents: list[str] = []
        obs_space = spaces.Box(self.core.obs_low, self.core.obs_high, dtype=np.float32)
        self.observation_spaces = {a: obs_space for a in self.possible_agents}
        self.action_spaces = {a: action_space for a in self.possible_agents}
        self.state_space = spaces.Box(self.core.obs_low, self.core.obs_high, dtype=np.float32)
        self.np_random, _ = seeding.np_random(None)

    def _joint_action(self, actions: dict[str, Any]) -> Any:  # the agents' actions as one action of the core
        raise NotImplementedError

    def observation_space(self, agent: str) -> spaces.Space:
        return self.observation_spaces[agent]

    def action_space(self, agent: str) -> spaces.Space:
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
        info = self.core.reset_info()
        return self._observations(), {a: dict(info) for a in self.agents}

    def _observations(self) -> dict[str, np.ndarray]:
        return {a: self.core.agent_observation(i) for i, a in enumerate(self.possible_agents) if a in self.agents}

    def state(self) -> np.ndarray:
        return self.core.observation()

    def step(self, actions: dict[str, Any]):
        reward, terminated, info = self.core.step(self._joint_action(actions))
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
        return self._draw()
