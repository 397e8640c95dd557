"""One env of the batched world behind :class:`~impact_env.transport.gym_env.TransportEnv`'s interface, impact
events included: what a controller written for the pymunk env (the expert) flies unchanged.

    from impact_env.transport.batched.one_env import BatchedOneEnv

    env = BatchedOneEnv("corridor", thrust_noise=0.05)            # float64, eager: the parity mode
    obs, info = env.reset(seed=0)
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    info["impacts"]                                                 # the pymunk env's event dicts

The batched world counts the contacts that end (``info["impacts"]`` is a number there); the expert's
bookkeeping and identification read each contact's names, start time, duration and the bodies' velocities at
first touch and at separation. :class:`ImpactRecorder` rebuilds those events from the world's substeps, with
the pymunk world's conventions (:mod:`impact_env.transport.physics`): a contact starts in the substep whose
detection first finds it and ends in the one whose detection no longer does, both at that substep's start
time, with the velocities the bodies had then (the previous substep's, the post-impact velocity error added
to the object's separation velocity); the four walls are named ``wall``; the contacts that end in one substep
close in the pymunk world's fixed order of shapes, and at the episode's end the open ones close with the
current velocities. A few contacts (2 of 25 in a full-thrust corridor episode: an object pressed into a
wall, its gap within rounding of zero for several substeps) start or end one or two substeps from where
pymunk's do (``tests/impact_env/transport/batched/test_one_env.py``). ``impulse`` is the momentum change of the
contact's second body (its only body, against a wall or an obstacle) from first touch to separation: the
impulse summed over the contact when nothing else touched that body meanwhile (the batched solver does not
report impulses). The world runs eagerly (the compiled kernel fuses the substeps that the events need).
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from gymnasium import spaces

from impact_env.env_shell import check_render_options
from impact_env.errors import EnvConfigError
from impact_env.transport.batched.world import BatchedTransportWorld
from impact_env.transport.physics import WALL
from impact_env.transport.scenario import Scenario


class ImpactRecorder:
    """The impact events of env 0 of a world, rebuilt substep by substep (module docstring)."""

    def __init__(self, world: BatchedTransportWorld) -> None:
        sc, lay = world.scene, world.layout
        B = sc.n_bodies
        self.world, self.n_bodies = world, B
        self._flags = slice(lay.pair_on.start, lay.static_on.stop)
        # contact c: (rank of its first shape, rank of its second) with bodies 0..B-1, then the static shapes
        self.contacts = [tuple(p) for p in sc.pairs] + [(b, B + k) for k in range(sc.n_static) for b in range(B)]
        statics = [WALL] * 4 + [name for name in sc.static_names[4:]]
        self.shape_names = list(sc.names) + statics
        self.mass_kg = sc.mass_kg
        self.noise_index = {p: q for q, (p, _) in enumerate(sc.robot_object_pairs)}
        self.substeps, self.dt_s = sc.substeps, sc.dt_s
        self.step_index = 0
        self.reset()

    def reset(self) -> None:
        self.open: dict[int, tuple[float, tuple[float, float], tuple[float, float]]] = {}
        self.closed: list[dict[str, Any]] = []

    def _velocities(self, rows: torch.Tensor) -> list[tuple[float, float]]:
        B = self.n_bodies
        v = rows[2 * B: 4 * B, 0].reshape(2, B).T.tolist()
        return [tuple(x) for x in v] + [(0.0, 0.0)] * (len(self.shape_names) - B)

    def _event(self, c: int, start: tuple, t_end_s: float, va: tuple, vb: tuple) -> dict[str, Any]:
        i, j = self.contacts[c]
        t0, va0, vb0 = start
        body = j if j < self.n_bodies else i
        v0, v1 = (vb0, vb) if body == j else (va0, va)
        impulse = self.mass_kg[body] * math.hypot(v1[0] - v0[0], v1[1] - v0[1])
        return {"time": t0, "a": self.shape_names[i], "b": self.shape_names[j], "impulse": impulse,
                "a_velocity_before": list(va0), "b_velocity_before": list(vb0), "a_velocity_after": list(va),
                "b_velocity_after": list(vb), "duration": t_end_s - t0}

    def substep(self, s: int, before: torch.Tensor, after: torch.Tensor, noise: torch.Tensor | None) -> None:
        """Called by the world after substep ``s`` of the current step with the rows before and after it."""
        was, now = before[self._flags, 0] > 0.5, after[self._flags, 0] > 0.5
        changed = (was != now).nonzero().flatten().tolist()
        if not changed:
            return
        t_s = (self.step_index * self.substeps + s) * self.dt_s
        v = self._velocities(before)  # what the bodies had when this substep's detection ran
        ended = []
        for c in changed:
            i, j = self.contacts[c]
            if bool(now[c]):
                self.open[c] = (t_s, v[i], v[j])
                continue
            start = self.open.pop(c, None)
            if start is None:
                continue
            va, vb = v[i], v[j]
            if noise is not None and c in self.noise_index:
                ex, ey = noise[self.noise_index[c], :, 0].tolist()
                vb = (vb[0] + ex, vb[1] + ey)
            ended.append((self.contacts[c], self._event(c, start, t_s, va, vb)))
        self.closed.extend(event for _, event in sorted(ended, key=lambda x: x[0]))

    def take(self, flush: bool) -> list[dict[str, Any]]:
        """The events closed since the last call; ``flush`` (the episode's last step) closes the open ones too,
        in the order they started, with the current velocities."""
        if flush and self.open:
            t_s = (self.step_index + 1) * self.substeps * self.dt_s
            v = self._velocities(self.world.rows)
            for c, start in sorted(self.open.items(), key=lambda x: (x[1][0], self.contacts[x[0]])):
                i, j = self.contacts[c]
                self.closed.append(self._event(c, start, t_s, v[i], v[j]))
            self.open.clear()
        out, self.closed = self.closed, []
        return out


class BatchedOneEnv(gym.Env):
    """The batched world with one env, as a Gymnasium env with TransportEnv's spaces, reward and info.

    Args:
        scenario: a shipped scenario name, a path to a TOML file or a Scenario.
        render_mode: None or ``"rgb_array"``.
        render_width_px: width of a frame.
        dtype: the world's dtype (default float64, the parity mode).
        **options: the world's options (``reward_mode``, ``fuel_penalty``, ``restitution``, ``thrust_noise``,
            ``initial_position_noise_m``, ``impact_velocity_noise_mps``, ``contact_iterations``); not
            ``compile`` (module docstring).

    ``info`` holds ``robustness`` (m), ``is_success``, ``fuel_Ns``, ``time_s`` and ``impacts``, the events
    that ended in the step as dicts of the pymunk env's format. ``reset(seed=s)`` seeds the env's Philox
    streams with ``s``: the same distributions as the pymunk env's noise, not the same draws.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, scenario: Scenario | str, *, render_mode: str | None = None, render_width_px: int = 600,
                 dtype: torch.dtype = torch.float64, **options: Any) -> None:
        if "compile" in options:
            raise EnvConfigError("BatchedOneEnv runs the world eagerly (its impact events need the substeps); "
                                 "drop compile=")
        check_render_options(self.metadata, render_mode, render_width_px)
        self.world = BatchedTransportWorld(scenario, 1, dtype=dtype, **options)
        w = self.world
        self.scenario = w.scenario
        self.render_mode, self.render_width_px = render_mode, render_width_px
        self.metadata = dict(self.metadata, render_fps=round(1.0 / w.dt_s))
        self.observation_space = spaces.Box(w.obs_low, w.obs_high, dtype=np.float32)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(w.action_size,), dtype=np.float32)
        self.recorder = ImpactRecorder(w)
        w._substep_hook = self.recorder.substep

    @property
    def dt_s(self) -> float:
        """Simulated time per step (s)."""
        return self.world.dt_s

    @property
    def horizon_steps(self) -> int:
        """Steps per episode: the task's horizon."""
        return self.world.horizon_steps

    def _info(self, impacts: list[dict[str, Any]]) -> dict[str, Any]:
        w = self.world
        robustness = float(w.robustness[0])
        return {"robustness": robustness, "is_success": robustness > 0.0, "fuel_Ns": float(w.fuel_Ns[0]),
                "time_s": int(w.step_count[0]) * w.dt_s, "impacts": impacts}

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        if options:
            raise EnvConfigError(f"BatchedOneEnv.reset takes no options, got {sorted(options)}")
        obs = self.world.reset(seeds=None if seed is None else [seed])
        self.recorder.reset()
        return obs[0].cpu().numpy(), self._info([])

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        a = torch.as_tensor(np.asarray(action, dtype=np.float64)).reshape(1, -1)
        self.recorder.step_index = int(self.world.step_count[0])
        obs, reward, terminated, _, _ = self.world.step(a)
        done = bool(terminated[0])
        return obs[0].cpu().numpy(), float(reward[0]), done, False, self._info(self.recorder.take(flush=done))

    # gymnasium's Env.render returns RenderFrame | list[RenderFrame] | None with RenderFrame a type variable bound
    # to nothing, which no concrete return type matches; a frame here is a uint8 (H, W, 3) array
    def render(self) -> np.ndarray | None:  # type: ignore[override]
        if self.render_mode is None:
            return None
        return self.world.render_rgb(0, self.render_width_px)

    def close(self) -> None:
        for renderer in self.world._renderers.values():
            renderer.close()
        self.world._renderers.clear()
