"""The batched world as a Gymnasium ``VectorEnv``: what ``gymnasium.make_vec(id, num_envs=N,
vectorization_mode="vector_entry_point")`` returns for every impact-transport id.

    import gymnasium as gym
    import impact_env

    envs = gym.make_vec("impact_env/Corridor-v0", num_envs=1024, vectorization_mode="vector_entry_point")
    obs, infos = envs.reset(seed=0)                      # obs: numpy [1024, 22] float32
    obs, rewards, terminations, truncations, infos = envs.step(envs.action_space.sample())

It behaves as ``gym.make_vec(id, num_envs=N, vectorization_mode="sync")`` of the pymunk env would, with the
batched world's physics and noise streams (``docs/batched.md``): numpy in and out, spaces batched from the
Gym env's (``single_observation_space`` is ``TransportEnv``'s), float64 rewards, Gymnasium's default
**next-step autoreset** (``metadata["autoreset_mode"]``: the step after an env's episode ended returns its
reset observation, reward 0 and no termination, and ignores its action), and per-env ``infos`` in
Gymnasium's vector form (``infos["robustness"]`` and the mask ``infos["_robustness"]``; also ``is_success``,
``fuel_Ns``, ``time_s`` and ``impacts``, the number of contacts that ended in the step). ``max_episode_steps``
(set by ``make_vec`` from the id's registration) truncates as Gymnasium's ``TimeLimit`` does: at the horizon
an episode is both terminated and truncated.

``render_mode="rgb_array"``: ``render()`` returns a sequence of ``num_envs`` uint8 (H, W, 3) frames that draws
an env's frame only when it is read, so ``gymnasium.wrappers.vector.RecordVideo(envs, folder,
record_first_only=True)`` draws one env per step of a batch of thousands (without ``record_first_only`` it
tiles every env: keep such batches small).
torch is imported here only: ``import impact_env`` stays free of it, and the ids' registration names
:func:`impact_env.transport.vector_entry.make_vector_env`, which imports this module when a vector env is made.
``gymnasium.make_vec(id, num_envs=N)`` without a mode picks it too (Gymnasium prefers an id's vector entry
point); ``vectorization_mode="sync"`` makes N pymunk envs.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import torch
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from impact_env.env_shell import check_render_options, required
from impact_env.errors import EnvConfigError
from impact_env.transport.batched.world import BatchedTransportWorld
from impact_env.transport.gym_env import SCENARIO_EXAMPLE, SCENARIO_HINT
from impact_env.transport.scenario import Scenario

INFO_KEYS = ("robustness", "is_success", "fuel_Ns", "time_s", "impacts")


class BatchFrames(Sequence[np.ndarray]):
    """``num_envs`` frames of the batch's state when it was made; frame i is drawn when it is first read
    (RecordVideo reads all of them, or only the first with ``record_first_only=True``)."""

    def __init__(self, envs: TransportVectorEnv) -> None:
        self._envs, self._world = envs, envs.world
        self._frames: dict[int, np.ndarray] = {}
        self._moves = envs._moves  # to refuse a frame read after the batch moved on

    def __len__(self) -> int:
        return self._world.num_envs

    def __getitem__(self, index: Any) -> Any:
        if isinstance(index, slice):
            return [self[i] for i in range(*index.indices(len(self)))]
        if isinstance(index, bool) or not isinstance(index, (int, np.integer)) or not -len(self) <= index < len(self):
            raise IndexError(f"env index must be an integer in 0..{len(self) - 1}, got {index!r}")
        i = int(index) % len(self)
        if i not in self._frames:
            if self._envs._moves != self._moves:
                raise EnvConfigError("these frames were made before the last step or reset; call render() again")
            self._frames[i] = self._world.render_rgb(i, self._envs.render_width_px)
        return self._frames[i]


class TransportVectorEnv(VectorEnv):
    """``num_envs`` envs of one scenario as a Gymnasium VectorEnv (module docstring).

    Args:
        scenario: a shipped scenario name, a path to a TOML file or a Scenario (the ids set it).
        num_envs: N.
        render_mode: None or ``"rgb_array"``.
        render_width_px: width of a frame.
        max_episode_steps: truncate episodes after this many steps (``make_vec`` passes the id's).
        device, dtype, compile, contact_iterations: the batched world's (default CPU, float32, eager).
        **options: the Gym env's options (``reward_mode``, ``fuel_penalty``, ``restitution``, ``thrust_noise``,
            ``initial_position_noise_m``, ``impact_velocity_noise_mps``), checked by the world.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10, "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, scenario: Scenario | str | None = None, num_envs: int = 1, *, render_mode: str | None = None,
                 render_width_px: int = 600,
                 max_episode_steps: int | None = None, device: torch.device | str | None = None,
                 dtype: torch.dtype = torch.float32, compile: bool = False, contact_iterations: int = 10,
                 **options: Any) -> None:
        scenario = required(scenario, "scenario", SCENARIO_HINT, SCENARIO_EXAMPLE.replace("gym.make", "gym.make_vec"))
        check_render_options(self.metadata, render_mode, render_width_px)
        if max_episode_steps is not None and not (type(max_episode_steps) is int and max_episode_steps >= 1):
            raise EnvConfigError(f"max_episode_steps must be a positive integer or None, got {max_episode_steps!r}")
        self.world = BatchedTransportWorld(scenario, num_envs, device=device, dtype=dtype, compile=compile,
                                           contact_iterations=contact_iterations, **options)
        w = self.world
        self.scenario = w.scenario
        self.num_envs = num_envs
        self.render_mode, self.render_width_px = render_mode, render_width_px
        self.metadata = dict(self.metadata, render_fps=round(1.0 / w.dt_s))
        self.max_episode_steps = max_episode_steps
        self.single_observation_space = spaces.Box(w.obs_low, w.obs_high, dtype=np.float32)
        self.single_action_space = spaces.Box(-1.0, 1.0, shape=(w.action_size,), dtype=np.float32)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self._autoreset = np.zeros(num_envs, dtype=bool)
        self._elapsed = np.zeros(num_envs, dtype=np.int64)
        self._moves = 0  # steps and resets so far (BatchFrames)

    @property
    def dt_s(self) -> float:
        """Simulated time per step (s)."""
        return self.world.dt_s

    @property
    def horizon_steps(self) -> int:
        """Steps per episode: the task's horizon."""
        return self.world.horizon_steps

    def _infos(self, info: dict[str, torch.Tensor], mask: np.ndarray) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for key in INFO_KEYS:
            out[key] = info[key].detach().cpu().numpy()
            out[f"_{key}"] = mask.copy()
        return out

    def _state_info(self) -> dict[str, torch.Tensor]:
        """The info of envs that did not move (just reset): their current values, no impacts."""
        w = self.world
        return {"robustness": w.robustness, "is_success": w.robustness > 0.0, "fuel_Ns": w.fuel_Ns,
                "time_s": w.step_count.to(w.dtype) * w.dt_s, "impacts": torch.zeros_like(w.step_count)}

    def reset(self, *, seed: int | Sequence[int] | None = None,
              options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset every env (``seed``: env i gets seed + i, or one seed per env); ``options`` must be None or
        ``{"reset_mask": [N] bool}`` (Gymnasium's partial reset)."""
        self._moves += 1
        mask = None
        if options:
            unknown = set(options) - {"reset_mask"}
            if unknown:
                raise EnvConfigError(f"reset options may only hold 'reset_mask', got {sorted(unknown)}")
            mask = np.asarray(options["reset_mask"], dtype=bool)
        super().reset(seed=seed if isinstance(seed, (int, np.integer)) or seed is None else None)
        m = None if mask is None else torch.as_tensor(mask, device=self.world.device)
        obs = self.world.reset(seeds=seed, mask=m)
        done = np.ones(self.num_envs, dtype=bool) if mask is None else mask
        self._autoreset[done] = False
        self._elapsed[done] = 0
        return obs.cpu().numpy(), self._infos(self._state_info(), done)

    def step(self, actions: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """One step of every env; the envs whose episode ended at the previous step are reset instead."""
        self._moves += 1
        resetting = self._autoreset.copy()
        a = torch.as_tensor(np.asarray(actions), device=self.world.device)
        if resetting.all():  # every episode ended together (the usual case: one horizon): nothing moves
            self.world._check_actions(a)
            self._elapsed[:] = 0
            obs = self.world.reset()
            zeros = np.zeros(self.num_envs)
            self._autoreset[:] = False
            return obs.cpu().numpy(), zeros, zeros.astype(bool), zeros.astype(bool), self._infos(
                self._state_info(), np.ones(self.num_envs, bool))
        if resetting.any():
            m = torch.as_tensor(resetting, device=self.world.device)
            self.world.reset(mask=m)
            self._elapsed[resetting] = 0
            obs, reward, ended, _, info = self.world.step(a, active=~m)
        else:
            obs, reward, ended, _, info = self.world.step(a)
        stepped = ~resetting
        self._elapsed[stepped] += 1
        terminated = ended.cpu().numpy()
        truncated = np.zeros(self.num_envs, dtype=bool)
        if self.max_episode_steps is not None:
            truncated = stepped & (self._elapsed >= self.max_episode_steps)
        self._autoreset = stepped & (terminated | truncated)
        rewards = reward.detach().cpu().numpy().astype(np.float64)
        return obs.cpu().numpy(), rewards, terminated, truncated, self._infos(info, np.ones(self.num_envs, bool))

    # gymnasium's VectorEnv.render returns tuple[RenderFrame, ...] with RenderFrame a type variable bound to
    # nothing, which no concrete return type matches; BatchFrames is a sequence of frames
    def render(self) -> BatchFrames | None:  # type: ignore[override]
        """The envs' frames now (``render_mode="rgb_array"``): a sequence of ``num_envs`` uint8 (H, W, 3)
        arrays, each drawn when it is first read."""
        if self.render_mode is None:
            return None
        return BatchFrames(self)

    def close_extras(self, **kwargs: Any) -> None:
        world = getattr(self, "world", None)  # None: the constructor raised
        if world is not None:
            world.close()


