"""The batched world as a stable-baselines3 ``VecEnv``, with SB3's conventions (numpy, same-step reset).

    from stable_baselines3 import PPO
    from impact_env.transport.batched.sb3_vec_env import TransportSB3VecEnv

    venv = TransportSB3VecEnv("corridor", num_envs=256, thrust_noise=0.05)
    PPO("MlpPolicy", venv, n_steps=64, batch_size=4096).learn(100_000)

``step_wait`` returns (obs [N, 7 B + 1] float32, rewards [N] float32, dones [N] bool, infos: a list of N dicts).
An env whose episode ends is reset in the same step, as SB3's own VecEnvs do: its ``dones`` entry is True, the
observation returned is the first of its next episode, and its info holds ``terminal_observation`` (the last
observation of the episode that ended) and ``TimeLimit.truncated`` (``truncated and not terminated``: always
False here, the horizon is a termination). Every info holds ``robustness`` (m), ``is_success``, ``fuel_Ns``,
``time_s`` and ``impacts`` (contacts that ended in the step). ``seed(s)`` seeds the next ``reset()`` (env i gets
s + i); ``render_env_indices`` choose the envs ``get_images()`` draws. Needs stable-baselines3 (the ``[rl]``
extra).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3.common.vec_env.base_vec_env import VecEnv, VecEnvIndices

from impact_env.errors import EnvConfigError
from impact_env.transport.batched.world import BatchedTransportWorld
from impact_env.transport.scenario import Scenario


class TransportSB3VecEnv(VecEnv):
    """``num_envs`` envs of one scenario for stable-baselines3 (module docstring).

    Args:
        scenario: a shipped scenario name, a path to a TOML file or a Scenario.
        num_envs: N.
        world: instead of ``scenario`` and ``num_envs``, a world built already: a
            :class:`~impact_env.transport.batched.BatchedTransportWorld` or a
            :class:`~impact_env.transport.batched.family_world.TaskFamilyWorld` (many tasks of a family).
        render_env_indices: the envs ``get_images()`` / ``render()`` draw (default the first).
        render_width_px: width of a frame.
        **world_options: :class:`~impact_env.transport.batched.BatchedTransportWorld`'s options.
    """

    metadata: dict[str, Any] = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, scenario: Scenario | str | None = None, num_envs: int | None = None, *, world: Any = None,
                 render_env_indices: Sequence[int] = (0,), render_width_px: int = 600, **world_options: Any) -> None:
        if world is None:
            if scenario is None or num_envs is None:
                raise EnvConfigError("give a scenario and num_envs, or a world")
            world = BatchedTransportWorld(scenario, num_envs, **world_options)
        elif scenario is not None or num_envs is not None or world_options:
            raise EnvConfigError("give a scenario and num_envs (and world options), or a world built already, not both")
        self.world = w = world
        num_envs = w.num_envs
        indices = tuple(render_env_indices)
        if not indices or any(isinstance(i, bool) or not isinstance(i, (int, np.integer)) or not 0 <= i < num_envs
                              for i in indices):
            raise EnvConfigError(f"render_env_indices must be env indices in 0..{num_envs - 1}, got {indices!r}")
        self.render_env_indices = tuple(int(i) for i in indices)
        self.render_width_px = render_width_px
        observation_space = spaces.Box(w.obs_low, w.obs_high, dtype=np.float32)
        action_space = spaces.Box(-1.0, 1.0, shape=(w.action_size,), dtype=np.float32)
        self.render_mode = "rgb_array"  # read by VecEnv.__init__ (through get_attr)
        super().__init__(num_envs, observation_space, action_space)
        self.metadata = dict(self.metadata, render_fps=round(1.0 / w.dt_s))
        self.scenario = w.scenario
        self._actions: torch.Tensor | None = None

    def reset(self) -> np.ndarray:
        seeds = None if all(s is None for s in self._seeds) else [0 if s is None else int(s) for s in self._seeds]
        obs = self.world.reset(seeds=seeds)
        self._reset_seeds()
        self._reset_options()
        return obs.cpu().numpy()

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = torch.as_tensor(np.asarray(actions), device=self.world.device)

    def step_wait(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict[str, Any]]]:
        if self._actions is None:
            raise EnvConfigError("step_wait() without step_async(actions)")
        obs, reward, terminated, truncated, info = self.world.step(self._actions)
        self._actions = None
        done = terminated | truncated
        obs_np = obs.cpu().numpy()
        host = {k: v.detach().cpu().numpy() for k, v in info.items()}
        infos = [{"robustness": float(host["robustness"][i]), "is_success": bool(host["is_success"][i]),
                  "fuel_Ns": float(host["fuel_Ns"][i]), "time_s": float(host["time_s"][i]),
                  "impacts": int(host["impacts"][i])} for i in range(self.num_envs)]
        if "task_index" in host:  # a TaskFamilyWorld: which of its tasks each env runs
            for info_of_env, task in zip(infos, host["task_index"].tolist()):
                info_of_env["task_index"] = int(task)
        done_np = done.cpu().numpy()
        if done_np.any():
            truncated_np = (truncated & ~terminated).cpu().numpy()
            for i in np.flatnonzero(done_np):
                infos[i]["terminal_observation"] = obs_np[i].copy()
                infos[i]["TimeLimit.truncated"] = bool(truncated_np[i])
            obs_np = self.world.reset(mask=done).cpu().numpy()
        return obs_np, reward.detach().cpu().numpy().astype(np.float32), done_np, infos

    def close(self) -> None:
        self.world.close()

    def get_images(self) -> Sequence[np.ndarray | None]:
        return [self.world.render_rgb(i, self.render_width_px) for i in self.render_env_indices]

    # the attribute plumbing of a VecEnv: every env of the batch is the same world, so attributes are the world's
    def _indices(self, indices: VecEnvIndices) -> list[int]:
        if indices is None:
            return list(range(self.num_envs))
        return [indices] if isinstance(indices, int) else list(indices)

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        value = getattr(self if attr_name in ("render_mode", "metadata", "scenario") else self.world, attr_name)
        return [value for _ in self._indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        raise EnvConfigError(f"the envs of a batched world share their attributes; {attr_name!r} cannot be set per env")

    def env_method(self, method_name: str, *method_args: Any, indices: VecEnvIndices = None,
                   **method_kwargs: Any) -> list[Any]:
        raise EnvConfigError(f"the envs of a batched world have no methods of their own ({method_name!r}); use .world")

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None) -> list[bool]:
        return [False for _ in self._indices(indices)]
