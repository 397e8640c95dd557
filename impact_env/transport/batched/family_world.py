"""Many tasks of one family in one batch, each env seeing its task through the family's padded layout.

    from impact_env.transport.batched.family_world import TaskFamilyWorld
    from impact_env.transport.batched.sb3_vec_env import TransportSB3VecEnv

    world = TaskFamilyWorld("throw_and_catch", tasks=range(64), envs_per_task=8, thrust_noise=0.05)
    obs = world.reset(seeds=0)                  # [512, 73]: the goal-conditioned observation of every env
    venv = TransportSB3VecEnv(world=world)      # stable-baselines3 trains one policy on all 64 tasks

A goal-conditioned policy learns one family from many tasks, so its batch must hold many tasks at once.
:class:`~impact_env.transport.batched.BatchedTransportWorld` holds one scenario (its tensors are shaped by the
scenario's bodies, contacts and task formula), so this class keeps one such world per task, ``envs_per_task``
envs each, and puts them side by side: env ``k * envs_per_task + i`` is env ``i`` of task ``k``'s world.
Observations are the family's padded layout
(:class:`~impact_env.transport.task_observation.TaskObservation`, as the family env ids of
:mod:`impact_env.transport.family_env` give them), computed on the tensors with the layout's own scatter map,
and actions are padded to the family's largest robot count (a task's world takes its first ``3 R`` numbers).
Dynamics, noise, rewards and episode ends are each task world's own, so a task's episodes are exactly those
of the batched world of its scenario, and an env's trajectory depends on its seed and task only.

A step costs one world step per task (each world's cost barely depends on its env count on a CPU), so a batch
of few tasks with many envs each runs faster than many tasks with few envs; the tasks a batch holds are its
training set. ``info["task_index"]`` ([N] int64) says which of ``tasks`` each env runs.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import torch

from impact_env.errors import EnvConfigError, ImpactEnvError
from impact_env.transport.batched.world import BatchedTransportWorld
from impact_env.transport.core import ACTION_PER_ROBOT, OBS_PER_BODY
from impact_env.transport.family_env import Task, family_task
from impact_env.transport.generate import FAMILY_LIMITS, check_family
from impact_env.transport.task_observation import TaskObservation, padded_spaces

__all__ = ["TaskFamilyWorld"]


class TaskFamilyWorld:
    """``len(tasks) * envs_per_task`` envs of a family's tasks with its padded observation (module docstring).

    Args:
        family: one of :data:`~impact_env.transport.generate.FAMILIES`; its limits fix the layout.
        tasks: generated-task seeds, scenario names or files, or :class:`Scenario` objects (as the family env
            ids take them). Every task must share the control period.
        envs_per_task: envs of each task's world.
        **world_options: :class:`BatchedTransportWorld`'s options (noise, reward mode, dtype, device, ...),
            the same for every task.
    """

    def __init__(self, family: str, tasks: Sequence[Task], envs_per_task: int, **world_options: Any) -> None:
        try:
            check_family(family, 0)
        except Exception as exc:
            raise EnvConfigError(str(exc)) from None
        if isinstance(tasks, (str, bytes)) or not isinstance(tasks, (Sequence, range)) or len(tasks) == 0:
            raise EnvConfigError(f"tasks must be a non-empty list of generated-task seeds, scenario names, files or "
                                 f"Scenario objects, got {tasks!r}")
        if isinstance(envs_per_task, bool) or not isinstance(envs_per_task, int) or envs_per_task < 1:
            raise EnvConfigError(f"envs_per_task must be an integer >= 1, got {envs_per_task!r}")
        self.family, self.limits = family, FAMILY_LIMITS[family]
        self.scenarios = [family_task(family, t) for t in tasks]
        self.layouts = [TaskObservation(sc, self.limits) for sc in self.scenarios]  # checks the counts
        periods = {sc.control_period_s for sc in self.scenarios}
        if len(periods) > 1:
            raise EnvConfigError(f"the tasks of one batch must share the control period, got {sorted(periods)} s")
        self.worlds = [BatchedTransportWorld(sc, envs_per_task, **world_options) for sc in self.scenarios]
        first = self.worlds[0]
        self.device, self.dtype, self.dt_s = first.device, first.dtype, first.dt_s
        self.envs_per_task, self.num_tasks = envs_per_task, len(self.worlds)
        self.num_envs = envs_per_task * self.num_tasks
        observation_space, action_space = padded_spaces(self.limits)
        self.obs_size, self.action_size = observation_space.shape[0], action_space.shape[0]
        self.obs_low = np.full(self.obs_size, -np.inf, dtype=np.float32)
        self.obs_high = np.full(self.obs_size, np.inf, dtype=np.float32)
        self.scenario = None  # many scenarios: see ``scenarios``
        self.task_index = torch.arange(self.num_tasks, device=self.device).repeat_interleave(envs_per_task)
        self._maps = []
        for layout, world in zip(self.layouts, self.worlds):
            base, columns, time_column, centres = layout.scatter()
            sources = [(j, OBS_PER_BODY * (world.n_robots + slot), cx, cy) for j, slot, cx, cy in centres]
            self._maps.append((torch.as_tensor(base, device=self.device), torch.as_tensor(columns, device=self.device),
                               time_column, sources))
        self._obs: torch.Tensor | None = None

    # ------------------------------------------------------------------------------------------ layout
    def _pad(self, k: int, obs: torch.Tensor) -> torch.Tensor:
        """Task ``k``'s world observations [n, 7 B + 1] in the family's layout [n, obs_size] (as
        :meth:`TaskObservation.__call__` does for one)."""
        base, columns, time_column, sources = self._maps[k]
        out = base.expand(obs.shape[0], -1).clone()
        out[:, columns] = obs[:, :-1].to(out.dtype)
        out[:, time_column] = obs[:, -1]
        for j, src, cx, cy in sources:
            out[:, j] = cx - obs[:, src]
            out[:, j + 1] = cy - obs[:, src + 1]
        return out

    def _parts(self, x: torch.Tensor | None) -> list[torch.Tensor | None]:
        n = self.envs_per_task
        return [None if x is None else x[k * n:(k + 1) * n] for k in range(self.num_tasks)]

    def _mask(self, mask: Any) -> torch.Tensor | None:
        if mask is None:
            return None
        m = torch.as_tensor(mask, device=self.device)
        if m.dtype != torch.bool or tuple(m.shape) != (self.num_envs,):
            raise EnvConfigError(f"mask must be a bool tensor of shape ({self.num_envs},), got {m.dtype} "
                                 f"{tuple(m.shape)}")
        return m

    # -------------------------------------------------------------------------------------------- API
    def reset(self, seeds: torch.Tensor | Sequence[int] | int | None = None,
              mask: torch.Tensor | None = None) -> torch.Tensor:
        """As :meth:`BatchedTransportWorld.reset` over the whole batch: an int seed gives env i seed + i (so task
        k's env j gets seed + k * envs_per_task + j), or N seeds; returns obs [N, obs_size] float32."""
        m = self._mask(mask)
        if isinstance(seeds, (int, np.integer)):
            seeds = int(seeds) + torch.arange(self.num_envs, device=self.device)
        elif seeds is not None:
            seeds = torch.as_tensor(seeds, device=self.device)
            if tuple(seeds.shape) != (self.num_envs,):
                raise EnvConfigError(f"seeds must be an int or {self.num_envs} ints, got shape {tuple(seeds.shape)}")
        outs = []
        for k, (world, part, own_seeds, before) in enumerate(zip(self.worlds, self._parts(m), self._parts(seeds),
                                                                  self._parts(self._obs))):
            if part is not None and before is not None and not bool(part.any()):
                outs.append(before)  # no env of this task restarts
            else:
                outs.append(self._pad(k, world.reset(seeds=own_seeds, mask=part)))
        self._obs = torch.cat(outs)
        return self._obs

    def step(self, actions: torch.Tensor, active: torch.Tensor | None = None) -> tuple[
            torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, dict[str, torch.Tensor]]:
        """Actions [N, action_size] (the family's padded action) for one control period; returns what
        :meth:`BatchedTransportWorld.step` does, observations in the padded layout, and ``info["task_index"]``."""
        if self._obs is None:
            raise ImpactEnvError("call reset() before step()")
        try:
            a = torch.as_tensor(actions, device=self.device)
        except (TypeError, ValueError, RuntimeError) as exc:
            raise EnvConfigError(f"actions must be a tensor of shape ({self.num_envs}, {self.action_size}): "
                                 f"{exc}") from None
        if tuple(a.shape) != (self.num_envs, self.action_size):
            raise EnvConfigError(f"actions must have shape ({self.num_envs}, {self.action_size}) (the family's padded "
                                 f"action), got {tuple(a.shape)}")
        active = self._mask(active)
        n = self.envs_per_task
        results = [world.step(a[k * n:(k + 1) * n, :ACTION_PER_ROBOT * world.n_robots], on)
                   for k, (world, on) in enumerate(zip(self.worlds, self._parts(active)))]
        obs = torch.cat([self._pad(k, r[0]) for k, r in enumerate(results)])
        reward = torch.cat([r[1] for r in results])
        terminated = torch.cat([r[2] for r in results])
        truncated = torch.cat([r[3] for r in results])
        info = {key: torch.cat([r[4][key] for r in results]) for key in results[0][4]}
        info["task_index"] = self.task_index
        self._obs = obs
        return obs, reward, terminated, truncated, info

    def observation(self) -> torch.Tensor:
        """[N, obs_size] float32: the padded observation after the last reset or step."""
        if self._obs is None:
            raise ImpactEnvError("call reset() before reading observations")
        return self._obs

    def render_rgb(self, env_index: int, width_px: int = 600) -> np.ndarray:
        """A uint8 (H, W, 3) frame of env ``env_index`` (its task's world draws it)."""
        if not 0 <= env_index < self.num_envs:
            raise EnvConfigError(f"env_index must be in 0..{self.num_envs - 1}, got {env_index}")
        k, i = divmod(env_index, self.envs_per_task)
        return self.worlds[k].render_rgb(i, width_px)

    def close(self) -> None:
        """Close every task world's renderers."""
        for world in self.worlds:
            world.close()
