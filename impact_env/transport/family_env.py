"""One Gymnasium env per task family: every episode a task of the family, its observation carrying the task.

    env = gymnasium.make("impact_env/GapsTasks-v0")                      # a fresh generated task per episode
    env = gymnasium.make("impact_env/GapsTasks-v0", tasks=[3, 8, 21])   # one of those generated tasks
    obs, info = env.reset(seed=0, options={"task": "corridor"})         # one chosen task (a seed, name or file)

A goal-conditioned policy trains on many tasks of one family and is tested on others, so its env must change
task between episodes while its spaces stay fixed. :class:`TaskFamilyEnv` does that: at each reset it takes
a task (a generated one, by seed, from :mod:`impact_env.transport.generate`; or one of ``tasks``, which may
also be scenario names, files or :class:`Scenario` objects, e.g. a training split), runs the ordinary
:class:`~impact_env.transport.gym_env.TransportEnv` on it and shows it through
:class:`~impact_env.transport.task_observation.TaskObservation` (the family's padded layout: bodies, time
left, timed region clauses, obstacles). Dynamics, reward, noise and termination are the transport env's: an
episode ends at its task's horizon, so episodes of one env differ in length. Which tasks to draw, and which
to hold out, is the caller's choice (``baselines.task_dataset.split_tasks`` makes the package's split);
without ``tasks`` the env draws generated seeds from its own generator, which a planner has not filtered,
so some tasks may be impossible. ``info["task"]`` names each episode's task.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from impact_env.errors import EnvConfigError
from impact_env.transport.generate import FAMILY_LIMITS, check_family, generate_task
from impact_env.transport.gym_env import TransportEnv
from impact_env.transport.scenario import Scenario, load_scenario
from impact_env.transport.task_observation import TaskObservation, padded_spaces

__all__ = ["FAMILY_IDS", "TaskFamilyEnv", "family_task"]

FAMILY_IDS = {
    "impact_env/ThrowAndCatchTasks-v0": "throw_and_catch",
    "impact_env/ObstacleAvoidanceTasks-v0": "obstacle_avoidance",
    "impact_env/GapsTasks-v0": "gaps",
    "impact_env/TimedVisitsTasks-v0": "timed_visits",
}
CACHED_TASKS = 32  # transport envs kept for tasks seen recently (building one costs a scenario load and a world)
TASK_SEEDS = 2**31  # a generated task's seed, drawn by the env when no ``tasks`` are given, is below this

Task = int | str | Path | Scenario


def family_task(family: str, task: Task) -> Scenario:
    """The scenario of a task given as a generated-task seed of ``family`` (int), a scenario name or file, or a
    Scenario."""
    if isinstance(task, Scenario):
        return task
    if isinstance(task, (int, np.integer)) and not isinstance(task, bool):
        return generate_task(family, int(task))
    if isinstance(task, (str, Path)):
        return load_scenario(task)
    raise EnvConfigError(f"a task is a generated-task seed (int), a scenario name or file, or a Scenario; got "
                         f"{task!r}")


class TaskFamilyEnv(gym.Env):
    """The transport env on one task of ``family`` per episode, with the family's goal-conditioned observation.

    Args:
        family: one of :data:`~impact_env.transport.generate.FAMILIES`.
        tasks: the tasks to draw from (each reset takes one at random from the env's generator, so
            ``reset(seed=s)`` fixes the task too): generated-task seeds (int), shipped scenario names, scenario
            files or :class:`Scenario` objects. None: each reset draws a generated task's seed below 2**31.
        **env_kwargs: the transport env's own arguments (``reward_mode``, ``fuel_penalty``, ``thrust_noise``,
            ``initial_position_noise_m``, ``impact_velocity_noise_mps``, ``restitution``, ``render_mode``...).

    ``reset(options={"task": t})`` runs task ``t`` (any of the forms above) instead: an evaluation's loop.
    """

    metadata = {"render_modes": ["human", "rgb_array"], "render_fps": 10}

    def __init__(self, family: str, tasks: Sequence[Task] | None = None, **env_kwargs: Any) -> None:
        try:
            check_family(family, 0)
        except Exception as exc:
            raise EnvConfigError(str(exc)) from None
        if "scenario" in env_kwargs:
            raise EnvConfigError("a task family env takes tasks=[...] (seeds, names, files or Scenario objects), "
                                 "not scenario=")
        self.family, self.limits, self.env_kwargs = family, FAMILY_LIMITS[family], dict(env_kwargs)
        self.render_mode = env_kwargs.get("render_mode")
        if tasks is not None:
            if isinstance(tasks, (str, bytes, Path, Scenario)) or not isinstance(tasks, Sequence) or not tasks:
                raise EnvConfigError(f"tasks must be a non-empty list of generated-task seeds, scenario names, files "
                                     f"or Scenario objects, got {tasks!r}")
            tasks = list(tasks)
            # a bad first task (an unknown name, a file that does not load, more bodies than the family's layout
            # holds) fails here with its own message; the others when they are drawn
            TaskObservation(self._scenario(tasks[0]), self.limits)
        self.tasks = tasks
        self._envs: OrderedDict[Any, tuple[TransportEnv, TaskObservation]] = OrderedDict()
        self.env: TransportEnv | None = None
        self.task_observation: TaskObservation | None = None
        self.observation_space, self.action_space = padded_spaces(self.limits)

    # -------------------------------------------------------------------------------------------- tasks
    def _scenario(self, task: Task) -> Scenario:
        return family_task(self.family, task)

    def _open(self, task: Task) -> tuple[TransportEnv, TaskObservation]:
        key = task if not isinstance(task, Path) else str(task)
        if key in self._envs:
            self._envs.move_to_end(key)
            return self._envs[key]
        scenario = self._scenario(task)
        pair = (TransportEnv(scenario, **self.env_kwargs), TaskObservation(scenario, self.limits))
        self._envs[key] = pair
        while len(self._envs) > CACHED_TASKS:
            _, (old, _) = self._envs.popitem(last=False)
            old.close()
        return pair

    # -------------------------------------------------------------------------------------------- gym API
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        options = dict(options or {})
        if "task" in options:
            task = options.pop("task")
        elif self.tasks is None:
            task = int(self.np_random.integers(TASK_SEEDS))
        else:
            task = self.tasks[int(self.np_random.integers(len(self.tasks)))]
        self.env, self.task_observation = self._open(task)
        obs, info = self.env.reset(seed=int(self.np_random.integers(2**63)), options=options or None)
        info["task"] = self.env.scenario.name
        return self.task_observation(obs), info

    def step(self, action):
        if self.env is None or self.task_observation is None:
            raise EnvConfigError("call reset() before step()")
        obs, reward, terminated, truncated, info = self.env.step(self.task_observation.unpad_action(action))
        info["task"] = self.env.scenario.name
        return self.task_observation(obs), reward, terminated, truncated, info

    @property
    def core(self):
        """The current task's :class:`~impact_env.transport.core.TransportCore` (after a reset), as
        :func:`impact_env.rollout.run_episode` reads it from any transport env."""
        if self.env is None:
            raise EnvConfigError("call reset() before reading the current task's core")
        return self.env.core

    def render(self):
        return None if self.env is None else self.env.render()

    def close(self) -> None:
        for env, _ in self._envs.values():
            env.close()
        self._envs.clear()
        self.env = None
