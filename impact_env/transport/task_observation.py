"""A goal-conditioned observation: the bodies padded to a family's maximum counts, plus the task itself.

    obs_map = TaskObservation(scenario, FAMILY_LIMITS["gaps"])
    padded = obs_map(env_observation)             # shape (obs_map.size,), the same for every gaps task
    env = TaskConditioned(TransportEnv(scenario), FAMILY_LIMITS["gaps"])   # the same as a wrapper

One policy per family must read every task of it, so the observation has a fixed layout
(:class:`~impact_env.transport.generate.FamilyLimits` gives the counts; missing slots are zeros with a
``present`` flag of 0). In order, float32:

1. per robot slot, then per object slot: ``present, x, y, vx, vy, cos, sin, omega`` (m, m/s, rad/s; the
   environment's own numbers);
2. the fraction of the episode's time left (the environment's last entry);
3. per region slot, one per ``F[a,b] in(O, R)`` or ``G[a,b] in(O, R)`` of the task, in the task's order:
   ``present, xmin, xmax, ymin, ymax`` of R's bounding box (m), ``cx - x_O, cy - y_O`` (R's centre relative
   to its object, m), ``a / tf, b / tf``, ``1`` for F (eventually) or ``0`` for G (always), then one-hot
   the object's slot;
4. per obstacle slot: ``present``, then its vertices ``x, y`` (m), padded to the family's vertex count by
   repeating the last vertex (so the padded polygon is the same polygon).

The action is padded the same way: :meth:`TaskObservation.unpad_action` keeps the first
``3 * n_robots`` numbers of a ``3 * limits.robots`` action. A scenario with more of anything than the
limits is an :class:`~impact_env.errors.EnvConfigError` naming the count.
"""

from __future__ import annotations

import re
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from impact_env.errors import EnvConfigError
from impact_env.transport.core import ACTION_PER_ROBOT, OBS_PER_BODY
from impact_env.transport.generate import FamilyLimits
from impact_env.transport.scenario import Scenario

__all__ = ["TaskConditioned", "TaskObservation", "padded_spaces", "task_clauses"]

_CLAUSE = re.compile(r"([FG])\s*\[\s*([0-9.eE+-]+)\s*,\s*([0-9.eE+-]+)\s*\]\s*\(?\s*in\(\s*(\w+)\s*,\s*(\w+)\s*\)")


def task_clauses(scenario: Scenario) -> list[tuple[str, float, float, str, str]]:
    """The task's timed region clauses ``(op, a_s, b_s, body, region)``: every ``F[a,b] in(B, R)`` and
    ``G[a,b] in(B, R)`` whose body is an object, in the order the task writes them."""
    objects = {o.name for o in scenario.objects}
    regions = {r.name for r in scenario.regions + scenario.obstacles}
    out = []
    for op, a, b, body, region in _CLAUSE.findall(scenario.task):
        if body in objects and region in regions:
            out.append((op, float(a), float(b), body, region))
    return out


class TaskObservation:
    """The padded, task-carrying observation of one scenario under a family's limits (module docstring)."""

    BODY = 1 + OBS_PER_BODY

    def __init__(self, scenario: Scenario, limits: FamilyLimits) -> None:
        self.scenario, self.limits = scenario, limits
        sc = scenario
        self.clauses = task_clauses(sc)
        for what, n, most in (("robots", len(sc.robots), limits.robots), ("objects", len(sc.objects), limits.objects),
                              ("timed region clauses", len(self.clauses), limits.regions),
                              ("obstacles", len(sc.obstacles), limits.obstacles)):
            if n > most:
                raise EnvConfigError(f"scenario {sc.name!r} has {n} {what}; this observation pads to at most {most}")
        for o in sc.obstacles:
            if len(o.polygon.vertices) > limits.obstacle_vertices:
                raise EnvConfigError(f"obstacle {o.name!r} of {sc.name!r} has {len(o.polygon.vertices)} vertices; this "
                                     f"observation pads to at most {limits.obstacle_vertices}")
        self.n_robots, self.n_objects = len(sc.robots), len(sc.objects)
        self.region_size, self.obstacle_size, self.bodies_size, self.size, self.action_size = _sizes(limits)
        # the constant part (regions without the object-relative centre, obstacles), built once
        self._static = np.zeros(self.size, dtype=np.float32)
        self._object_slot = {o.name: i for i, o in enumerate(sc.objects)}
        regions = sc.region_map()
        self._centres = []
        for k, (op, a, b, body, region) in enumerate(self.clauses):
            xmin, xmax, ymin, ymax = regions[region].bounds
            j = self.bodies_size + 1 + k * self.region_size
            self._static[j:j + 5] = (1.0, xmin, xmax, ymin, ymax)
            self._static[j + 7:j + 10] = (a / sc.tf_s, b / sc.tf_s, 1.0 if op == "F" else 0.0)
            self._static[j + 10 + self._object_slot[body]] = 1.0
            self._centres.append((j + 5, self._object_slot[body], 0.5 * (xmin + xmax), 0.5 * (ymin + ymax)))
        base = self.bodies_size + 1 + self.region_size * limits.regions
        for m, o in enumerate(sc.obstacles):
            v = np.asarray(o.polygon.vertices, dtype=np.float32)
            v = np.vstack([v, np.repeat(v[-1:], limits.obstacle_vertices - len(v), axis=0)])
            j = base + m * self.obstacle_size
            self._static[j] = 1.0
            self._static[j + 1:j + self.obstacle_size] = v.reshape(-1)
        # where each environment body row goes: robots to the first slots, objects after the robot slots
        self._rows = [1 + self.BODY * i for i in range(self.n_robots)] + [
            1 + self.BODY * (limits.robots + i) for i in range(self.n_objects)]

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        """The padded observation of one environment observation (``7 n_bodies + 1`` numbers)."""
        obs = np.asarray(observation, dtype=np.float32)
        n = self.n_robots + self.n_objects
        if obs.shape != (OBS_PER_BODY * n + 1,):
            raise EnvConfigError(f"observation must have shape ({OBS_PER_BODY * n + 1},) for {self.scenario.name!r}, "
                                 f"got {obs.shape}")
        out = self._static.copy()
        rows = obs[:-1].reshape(n, OBS_PER_BODY)
        for i, start in enumerate(self._rows):
            out[start - 1] = 1.0
            out[start:start + OBS_PER_BODY] = rows[i]
        out[self.bodies_size] = obs[-1]
        for j, slot, cx, cy in self._centres:
            ox, oy = rows[self.n_robots + slot, 0:2]
            out[j:j + 2] = (cx - ox, cy - oy)
        return out

    def scatter(self) -> tuple[np.ndarray, np.ndarray, int, list[tuple[int, int, float, float]]]:
        """Where :meth:`__call__` puts each number, for a batched implementation of it
        (:class:`~impact_env.transport.batched.family_world.TaskFamilyWorld`): ``(base, columns, time_column,
        centres)``. ``base`` is the padded observation before the bodies are written (the task's constant
        part and every present body's flag); the environment observation's body numbers ``obs[:-1]`` go to
        ``columns`` and its time left to ``time_column``; each ``(j, slot, cx, cy)`` of ``centres`` writes the
        region centre relative to object ``slot`` at columns ``j, j + 1``."""
        base = self._static.copy()
        columns: list[int] = []
        for start in self._rows:
            base[start - 1] = 1.0
            columns.extend(range(start, start + OBS_PER_BODY))
        return base, np.asarray(columns, dtype=np.int64), self.bodies_size, list(self._centres)

    def pad_action(self, action: np.ndarray) -> np.ndarray:
        """A ``3 n_robots`` action padded with zeros to ``3 limits.robots``."""
        out = np.zeros(self.action_size, dtype=np.float32)
        out[:ACTION_PER_ROBOT * self.n_robots] = np.asarray(action, dtype=np.float32).reshape(-1)
        return out

    def unpad_action(self, action: np.ndarray) -> np.ndarray:
        """The first ``3 n_robots`` numbers of a padded action."""
        a = np.asarray(action, dtype=np.float32).reshape(-1)
        if a.shape != (self.action_size,):
            raise EnvConfigError(f"a padded action has {self.action_size} numbers, got {a.shape}")
        return a[:ACTION_PER_ROBOT * self.n_robots]

    def spaces(self) -> tuple[spaces.Box, spaces.Box]:
        """(observation space, action space) of the padded layout: the same for every task of the family."""
        return padded_spaces(self.limits)


def _sizes(limits: FamilyLimits) -> tuple[int, int, int, int, int]:
    """(region slot, obstacle slot, bodies part, whole observation, action) sizes of the padded layout."""
    region_size = 10 + limits.objects
    obstacle_size = 1 + 2 * limits.obstacle_vertices
    bodies_size = TaskObservation.BODY * (limits.robots + limits.objects)
    size = bodies_size + 1 + region_size * limits.regions + obstacle_size * limits.obstacles
    return region_size, obstacle_size, bodies_size, size, ACTION_PER_ROBOT * limits.robots


def padded_spaces(limits: FamilyLimits) -> tuple[spaces.Box, spaces.Box]:
    """(observation space, action space) of a family's padded layout (they depend on its limits only)."""
    _, _, _, size, action_size = _sizes(limits)
    return (spaces.Box(-np.inf, np.inf, shape=(size,), dtype=np.float32),
            spaces.Box(-1.0, 1.0, shape=(action_size,), dtype=np.float32))


class TaskConditioned(gym.Wrapper):
    """A :class:`~impact_env.transport.gym_env.TransportEnv` seen through :class:`TaskObservation`: padded
    observations in, padded actions out (the padding robots' numbers are ignored)."""

    def __init__(self, env: gym.Env, limits: FamilyLimits) -> None:
        super().__init__(env)
        scenario = getattr(env.unwrapped, "scenario", None)
        if not isinstance(scenario, Scenario):
            raise EnvConfigError(f"TaskConditioned wraps a TransportEnv (an env with a Scenario), got "
                                 f"{type(env.unwrapped).__name__}")
        self.task_observation = TaskObservation(scenario, limits)
        self.observation_space, self.action_space = self.task_observation.spaces()

    def reset(self, **kwargs: Any):
        obs, info = self.env.reset(**kwargs)
        return self.task_observation(obs), info

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(self.task_observation.unpad_action(action))
        return self.task_observation(obs), reward, terminated, truncated, info
