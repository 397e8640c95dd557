"""BatchedTransportWorld: N episodes of one impact-transport scenario as one torch program.

The semantics are those of :class:`~impact_env.transport.core.TransportCore` (the pymunk environments' core):
the same options, checked by it, the same observation and action layout, rewards, termination and info,
for ``num_envs`` envs at once on any torch device, in float32 (default) or float64. Physics: the kernels
of :mod:`~impact_env.transport.batched.physics` (eager reference) and :mod:`~impact_env.transport.batched.fused`
(``compile=True``: torch.compile fuses a whole control period into one loop over the envs; the rare envs it
flags are redone by the reference). Noise: counter-based
Philox streams keyed by each env's seed (:mod:`~impact_env.transport.batched.philox`), so an env's
trajectory depends on its seed only, never on ``num_envs`` or its slot.

What differs from the pymunk environments, on purpose:

- every tensor is batch-first on the outside (``obs [N, 7 B + 1]``, actions ``[N, 3 R]``) and batch-last
  inside; rewards and robustness come in the world's dtype, observations in float32 as the Gym env's;
- ``info["impacts"]`` is the number of contacts that ended in the step, per env (the pymunk env lists the
  events), including, on the last step, the contacts still open;
- random draws come from Philox, not numpy: the same distributions, not the same numbers;
- stepping an env past its horizon is an error for the whole batch: reset the ended envs first
  (``reset(mask=terminated)``), which is what an autoreset wrapper does.
"""

from __future__ import annotations

import secrets
from collections.abc import Sequence
from typing import Any

import numpy as np
import torch

from impact_env.errors import ActionError, EnvConfigError, ImpactEnvError
from impact_env.stl import conjuncts
from impact_env.transport.batched import episode
from impact_env.transport.batched.fused import FusedKernel
from impact_env.transport.batched.monitor import BatchedMonitor, MonitorState
from impact_env.transport.batched.physics import ReferenceKernel, TensorKwargs, headings, world_forces
from impact_env.transport.batched.scene import build_scene
from impact_env.transport.batched.starts import draw_object_starts
from impact_env.transport.core import ACTION_PER_ROBOT, OBS_PER_BODY, TransportCore
from impact_env.transport.scenario import Scenario

DTYPES = (torch.float32, torch.float64)
MAX_CONTACT_ITERATIONS = 100
_NEVER = -(2 ** 62)  # "no impact yet" in the last-impact steps
# compiled kernels run on blocks of at most this many envs: measured on the 2-core machine, one thread, the
# fused period costs twice as much per env at 16,384 envs as at 4,096 (its buffers no longer fit the caches)
CHUNK_ENVS = 4096


def _slice(x: Any, lo: int, hi: int, batch_first: bool) -> Any:
    if isinstance(x, tuple):
        return tuple(_slice(v, lo, hi, batch_first) for v in x)
    if not isinstance(x, torch.Tensor):
        return x
    return (x[lo:hi] if batch_first else x[..., lo:hi]).contiguous()


def _merge(parts: list[Any], batch_first: bool) -> Any:
    if isinstance(parts[0], tuple):
        return tuple(_merge([p[i] for p in parts], batch_first) for i in range(len(parts[0])))
    if not isinstance(parts[0], torch.Tensor):
        return parts[0]
    return torch.cat(parts, dim=0 if batch_first else -1)


def in_chunks(fn: Any, args: tuple[Any, ...], num_envs: int, batch_first_in: tuple[int, ...] = (),
              batch_first_out: tuple[int, ...] = (), chunk: int = CHUNK_ENVS) -> tuple[Any, ...]:
    """``fn(*args)`` over blocks of at most ``chunk`` envs, as equal as possible (so at most two shapes are
    compiled), with the results joined. Tensors have the env axis last, except the arguments and results whose
    positions are in ``batch_first_in`` / ``batch_first_out``; tuples are split element by element."""
    if num_envs <= chunk:
        return fn(*args)
    n_blocks = -(-num_envs // chunk)
    size, extra = divmod(num_envs, n_blocks)
    outs, lo = [], 0
    for block in range(n_blocks):
        hi = lo + size + (block < extra)
        outs.append(fn(*(_slice(x, lo, hi, i in batch_first_in) for i, x in enumerate(args))))
        lo = hi
    return tuple(_merge([o[i] for o in outs], i in batch_first_out) for i in range(len(outs[0])))


class BatchedTransportWorld:
    """``num_envs`` envs of one scenario; see the module docstring for what matches the pymunk env.

    Args:
        scenario: a Scenario, a shipped scenario name or a path to a TOML file.
        num_envs: number of envs N (>= 1).
        device: torch device of every tensor (default CPU).
        dtype: torch.float32 (default) or torch.float64 for the physics and the STL monitor.
        reward_mode: as :class:`~impact_env.transport.core.TransportCore`, which checks it and the five below.
        fuel_penalty: as TransportCore.
        restitution: as TransportCore.
        thrust_noise: as TransportCore.
        initial_position_noise_m: as TransportCore.
        impact_velocity_noise_mps: as TransportCore.
        contact_iterations: impulse passes per substep where a body has several contacts (chipmunk: 10).
        compile: run each control period and the step's bookkeeping through torch.compile (CPU: inductor's
            C++). The first step compiles, about 2.5 minutes per scenario, num_envs, dtype and thread count on a
            2-core machine; later processes load inductor's cache in about 10 s.

    Shapes: N envs, B bodies, R robots, obs_size = 7 B + 1, action_size = 3 R.
    """

    def __init__(self, scenario: Scenario | str, num_envs: int, *, device: torch.device | str | None = None,
                 dtype: torch.dtype = torch.float32, reward_mode: str = "dense", fuel_penalty: float = 0.0,
                 restitution: float | None = None, thrust_noise: float = 0.0, initial_position_noise_m: float = 0.0,
                 impact_velocity_noise_mps: float = 0.0, contact_iterations: int = 10, compile: bool = False) -> None:
        core = TransportCore(scenario, reward_mode=reward_mode, fuel_penalty=fuel_penalty, restitution=restitution,
                             thrust_noise=thrust_noise, initial_position_noise_m=initial_position_noise_m,
                             impact_velocity_noise_mps=impact_velocity_noise_mps)
        if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
            raise EnvConfigError(f"num_envs must be an integer >= 1, got {num_envs!r}")
        if dtype not in DTYPES:
            raise EnvConfigError(f"dtype must be torch.float32 or torch.float64, got {dtype!r}")
        if isinstance(contact_iterations, bool) or not isinstance(contact_iterations, int) \
                or not 1 <= contact_iterations <= MAX_CONTACT_ITERATIONS:
            raise EnvConfigError(f"contact_iterations must be an integer in 1..{MAX_CONTACT_ITERATIONS}, "
                                 f"got {contact_iterations!r}")
        try:
            self.device = torch.device("cpu" if device is None else device)
            torch.zeros(1, device=self.device)
        except (RuntimeError, TypeError) as exc:
            raise EnvConfigError(f"device {device!r} is not usable: {exc}") from None
        self.scenario = core.scenario
        self.num_envs, self.dtype = num_envs, dtype
        self.reward_mode, self.fuel_penalty = reward_mode, float(fuel_penalty)
        self.thrust_noise = float(thrust_noise)
        self.initial_position_noise_m = float(initial_position_noise_m)
        self.impact_velocity_noise_mps = float(impact_velocity_noise_mps)
        self.n_robots, self.n_bodies = core.n_robots, core.n_bodies
        self.body_names = core.body_names
        self.dt_s, self.horizon_steps = core.dt_s, core.horizon_steps
        self.robustness_limit_m = core.robustness_limit_m
        self.obs_low, self.obs_high = core.obs_low, core.obs_high
        self.obs_size, self.action_size = core.obs_size, self.n_robots * ACTION_PER_ROBOT
        self.scene = build_scene(self.scenario, restitution)
        self.reference = ReferenceKernel(self.scene, self.device, dtype, contact_iterations)
        self.layout = self.reference.layout
        opts = TensorKwargs(device=self.device, dtype=dtype)
        N, B, R = num_envs, self.n_bodies, self.n_robots
        formulas = [self.scenario.formula]
        if reward_mode == "conjuncts":
            formulas += list(conjuncts(self.scenario.formula))
        self.monitor = BatchedMonitor(formulas, self.scenario.region_map(), self.dt_s, self.body_names, N,
                                      self.device, dtype)
        self._limits = torch.tensor(core.wrench_limits.T.copy(), **opts).reshape(3, R, 1)
        self._inv_inertia = torch.tensor(self.scene.inv_inertia[:R], **opts).reshape(R, 1)
        self._low = torch.tensor(self.obs_low, device=self.device)
        self._high = torch.tensor(self.obs_high, device=self.device)
        lay = self.layout
        init = torch.zeros(lay.n_rows, 1, **opts)
        for b in range(B):
            init[b] = self.scene.position_m[b][0]
            init[B + b] = self.scene.position_m[b][1]
            init[2 * B + b] = self.scene.velocity_mps[b][0]
            init[3 * B + b] = self.scene.velocity_mps[b][1]
        self._init_rows = init
        self._init_ang = torch.tensor(self.scene.heading_rad, **opts).reshape(B, 1)
        self._init_omg = torch.tensor(self.scene.angular_velocity_radps, **opts).reshape(B, 1)
        self.rows = init.expand(lay.n_rows, N).clone()
        self.ang, self.omg = self._init_ang.expand(B, N).clone(), self._init_omg.expand(B, N).clone()
        int64 = TensorKwargs(device=self.device, dtype=torch.int64)
        self.step_count = torch.zeros(N, **int64)
        self.seeds = torch.zeros(N, **int64)
        self.episodes = torch.zeros(N, **int64)
        self._seeded = torch.zeros(N, dtype=torch.bool, device=self.device)
        self.fuel_Ns = torch.zeros(N, **opts)
        self.robustness = torch.zeros(N, **opts)
        self._potential = torch.zeros(N, **opts)
        self.last_wrenches = torch.zeros(3, R, N, **opts)
        self.last_impact_step = torch.full((lay.n_contacts, N), _NEVER, **int64)
        self._obs: torch.Tensor | None = None
        self._renderers: dict[int, Any] = {}
        # called after each substep of the reference kernel with (substep, rows before, rows after, its impact
        # noise or None): how BatchedOneEnv rebuilds the impact events (one_env.py)
        self._substep_hook: Any = None
        self.compiled = bool(compile)
        self._epilogue, self._fused_period = self._epilogue_impl, None
        self._fused = FusedKernel(self.scene, dtype)
        if self.compiled:
            self._fused_period = torch.compile(self._fused_period_impl, fullgraph=True, dynamic=False)
            self._epilogue = torch.compile(self._epilogue_impl, fullgraph=True, dynamic=False)

    # ------------------------------------------------------------------------------------------- reset
    def _seeds(self, seeds: Any) -> torch.Tensor:
        if isinstance(seeds, (int, np.integer)) and not isinstance(seeds, bool):
            base = int(seeds)
            values = [base + i for i in range(self.num_envs)]  # Gymnasium's vector convention: seed + index
        else:
            values = torch.as_tensor(seeds).reshape(-1).tolist() if isinstance(seeds, torch.Tensor) else list(seeds)
            if len(values) != self.num_envs:
                raise EnvConfigError(f"seeds must be an int or {self.num_envs} ints (one per env), got {len(values)}")
        for s in values:
            if isinstance(s, bool) or not isinstance(s, (int, np.integer)) or not 0 <= int(s) < 2 ** 63:
                raise EnvConfigError(f"seeds must be integers in [0, 2**63), got {s!r}")
        return torch.tensor([int(s) for s in values], dtype=torch.int64, device=self.device)

    def _mask(self, mask: Any) -> torch.Tensor:
        if mask is None:
            return torch.ones(self.num_envs, dtype=torch.bool, device=self.device)
        m = torch.as_tensor(mask, device=self.device)
        if m.dtype != torch.bool or m.shape != (self.num_envs,):
            raise EnvConfigError(f"mask must be a bool tensor of shape ({self.num_envs},), got {m.dtype} "
                                 f"{tuple(m.shape)}")
        return m

    def reset(self, seeds: torch.Tensor | Sequence[int] | int | None = None,
              mask: torch.Tensor | None = None) -> torch.Tensor:
        """Start new episodes in the envs of ``mask`` ([N] bool, default all); returns obs [N, obs_size].

        ``seeds``: an int (env i gets seed + i), or N ints; only the masked envs take theirs, and their random
        streams restart. Without seeds, an env seeded before starts its next episode of the same stream, and
        an env never seeded gets a seed from the operating system.
        """
        m = self._mask(mask)
        if seeds is not None:
            new = self._seeds(seeds)
            self.seeds = torch.where(m, new, self.seeds)
            self.episodes = torch.where(m, 0, self.episodes)
            self._seeded = self._seeded | m
        else:
            fresh = m & ~self._seeded
            if bool(fresh.any()):
                drawn = torch.tensor([secrets.randbits(63) for _ in range(self.num_envs)], device=self.device)
                self.seeds = torch.where(fresh, drawn, self.seeds)
            self.episodes = torch.where(m & self._seeded, self.episodes + 1, self.episodes)
            self._seeded = self._seeded | m
        self._key = (self.seeds & 0xFFFFFFFF, (self.seeds >> 32) & 0xFFFFFFFF)  # Philox key words
        rows = torch.where(m, self._init_rows, self.rows)
        if self.initial_position_noise_m > 0 and self.scenario.objects:
            idx = m.nonzero().squeeze(1)
            starts = draw_object_starts(self.scenario, self.initial_position_noise_m, self.seeds[idx],
                                        self.episodes[idx]).to(self.dtype)
            B, R = self.n_bodies, self.n_robots
            rows[R:B, idx] = starts[0]
            rows[B + R:2 * B, idx] = starts[1]
        self.rows = rows
        self.ang = torch.where(m, self._init_ang, self.ang)
        self.omg = torch.where(m, self._init_omg, self.omg)
        self.step_count = torch.where(m, 0, self.step_count)
        self.fuel_Ns = torch.where(m, 0.0, self.fuel_Ns)
        self._potential = torch.where(m, 0.0, self._potential)
        self.last_wrenches = torch.where(m, 0.0, self.last_wrenches)
        self.last_impact_step = torch.where(m, _NEVER, self.last_impact_step)
        state = self.monitor.reset_state(self.monitor.state, m)
        state, values = self.monitor.update_state(state, self.positions(), self.step_count, m)
        self.monitor.state = state
        estimate = torch.clamp(values[0], -self.robustness_limit_m, self.robustness_limit_m)
        self.robustness = torch.where(m, estimate, self.robustness)
        self._obs = episode.observe(self.rows, self.ang, self.omg, self.step_count, self.horizon_steps, self._low,
                                    self._high)
        return self._obs

    # -------------------------------------------------------------------------------------------- step
    def _check_actions(self, actions: Any) -> torch.Tensor:
        try:
            a = torch.as_tensor(actions, device=self.device)
        except (TypeError, ValueError, RuntimeError) as exc:
            raise ActionError(f"actions must be a tensor of shape ({self.num_envs}, {self.action_size}): "
                              f"{exc}") from None
        shapes = ((self.num_envs, self.action_size), (self.num_envs, self.n_robots, ACTION_PER_ROBOT))
        if tuple(a.shape) not in shapes or not (a.dtype.is_floating_point or a.dtype in (torch.int32, torch.int64)):
            raise ActionError(f"actions must be numbers of shape {shapes[0]} or {shapes[1]} (Fx, Fy, torque per robot "
                              f"in [-1, 1]), got {a.dtype} {tuple(a.shape)}")
        return a.reshape(shapes[0]).to(self.dtype)

    def step(self, actions: torch.Tensor, active: torch.Tensor | None = None) -> tuple[
            torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, dict[str, torch.Tensor]]:
        """Apply actions [N, 3 R] (or [N, R, 3]) in [-1, 1] for one control period.

        Returns (obs [N, obs_size] float32, reward [N], terminated [N] bool, truncated [N] bool (all False:
        the horizon is part of the task), info) with info tensors ``robustness`` (m), ``is_success``,
        ``fuel_Ns`` (cumulative), ``time_s`` and ``impacts`` (contacts that ended in this step, int64).

        ``active`` ([N] bool, default all): the envs outside it do not move (their state, clock and random
        streams stay as they were; they return their current observation, reward 0, not terminated, 0
        impacts), which is what Gymnasium's next-step autoreset needs for the envs it has just reset.
        """
        if self._obs is None:
            raise ImpactEnvError("call reset() before step()")
        if active is not None:
            active = self._mask(active)
            if bool(active.all()):
                active = None
        if active is not None:
            return self._step_active(actions, active, self._obs)
        a = self._check_actions(actions)
        args = (a, self.ang, self.omg, self._key[0], self._key[1], self.step_count, self.episodes)
        if self._fused_period is None:
            w, fuel, force, ang, omg, noise, flags = self._prologue_impl(*args)
        else:
            w, fuel, force, ang, omg, noise, flags, rows, ended, redo = in_chunks(
                self._fused_period, (*args, self.rows), self.num_envs, batch_first_in=(0,))
        bad_action, ended_envs = flags.any(1).tolist()  # the step's one synchronisation (besides the redo check)
        if bad_action:
            envs = (~torch.isfinite(a).all(1)).nonzero().squeeze(1).tolist()
            raise ActionError(f"actions of envs {envs[:10]}{' ...' if len(envs) > 10 else ''} contain NaN or infinite "
                              "values; actions must be finite numbers in [-1, 1]")
        if ended_envs:
            envs = (self.step_count >= self.horizon_steps).nonzero().squeeze(1).tolist()
            raise ImpactEnvError(f"envs {envs[:10]}{' ...' if len(envs) > 10 else ''} reached the task's horizon "
                                 f"({self.horizon_steps} steps); reset them first: reset(mask=terminated)")
        if self._fused_period is None:
            rows, ended = self._reference_period(self.rows, w, force, noise)
        elif bool(redo.any()):  # rare: a body with two contacts, a centre inside an obstacle (see fused.py)
            idx = redo.nonzero().squeeze(1)
            r_rows, r_ended = self._reference_period(self.rows[:, idx], w[..., idx], force[..., idx],
                                                     None if noise is None else noise[..., idx])
            rows[:, idx], ended[:, idx] = r_rows, r_ended
        self.rows, self.ang, self.omg, self.last_wrenches = rows, ang, omg, w
        epilogue_args = (rows, ang, omg, self.step_count + 1, self.monitor.state, self._potential, self.fuel_Ns, fuel,
                         ended, self.last_impact_step)
        if self.compiled:
            out = in_chunks(self._epilogue, epilogue_args, self.num_envs, batch_first_out=(0,))
        else:
            out = self._epilogue(*epilogue_args)
        (obs, reward, self.robustness, self._potential, self.fuel_Ns, self.monitor.state, terminated, impacts,
         self.last_impact_step, self.step_count) = out
        self._obs = obs
        info = {"robustness": self.robustness, "is_success": self.robustness > 0.0, "fuel_Ns": self.fuel_Ns,
                "time_s": self.step_count.to(self.dtype) * self.dt_s, "impacts": impacts}
        return obs, reward, terminated, torch.zeros_like(terminated), info

    def _step_active(self, actions: Any, active: torch.Tensor, obs_before: torch.Tensor) -> tuple[
            torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, dict[str, torch.Tensor]]:
        """:meth:`step` of the envs of ``active`` only: every env is stepped (the others with zero actions, from
        a clock held below the horizon), then the others get their state back (``obs_before``: their observation)."""
        a = self._check_actions(actions)
        keep = ~active
        saved = (self.rows, self.ang, self.omg, self.last_wrenches, self.last_impact_step, self.step_count,
                 self.fuel_Ns, self.robustness, self._potential, self.monitor.state)
        if bool(((self.step_count >= self.horizon_steps) & active).any()):
            envs = ((self.step_count >= self.horizon_steps) & active).nonzero().squeeze(1).tolist()
            raise ImpactEnvError(f"envs {envs[:10]}{' ...' if len(envs) > 10 else ''} reached the task's horizon "
                                 f"({self.horizon_steps} steps); reset them first: reset(mask=terminated)")
        self.step_count = torch.where(keep, torch.clamp(self.step_count, max=self.horizon_steps - 1), self.step_count)
        obs, reward, terminated, truncated, info = self.step(torch.where(keep.unsqueeze(1), 0.0, a))

        def back(new: torch.Tensor, old: torch.Tensor, env_last: bool = True) -> torch.Tensor:
            return torch.where(keep if env_last else keep.reshape(-1, *([1] * (old.dim() - 1))), old, new)

        (self.rows, self.ang, self.omg, self.last_wrenches, self.last_impact_step) = (
            back(n, o) for n, o in zip((self.rows, self.ang, self.omg, self.last_wrenches, self.last_impact_step),
                                       saved[:5]))
        self.step_count, self.fuel_Ns, self.robustness, self._potential = (
            back(n, o) for n, o in zip((self.step_count, self.fuel_Ns, self.robustness, self._potential), saved[5:9]))
        acc, run, best = (back(n, o) for n, o in zip(self.monitor.state, saved[9]))
        self.monitor.state = (acc, run, best)
        self._obs = obs = back(obs, obs_before, env_last=False)
        reward = torch.where(keep, 0.0, reward)
        terminated = terminated & active
        info = {"robustness": self.robustness, "is_success": self.robustness > 0.0, "fuel_Ns": self.fuel_Ns,
                "time_s": self.step_count.to(self.dtype) * self.dt_s, "impacts": torch.where(keep, 0, info["impacts"])}
        return obs, reward, terminated, truncated, info

    def _reference_period(self, rows: torch.Tensor, w: torch.Tensor, force: torch.Tensor,
                          noise: torch.Tensor | None) -> tuple[torch.Tensor, torch.Tensor]:
        """The period's substeps by the reference kernel (eager), for all envs or the ones the fused kernel
        flagged: (rows after, contacts ended per contact)."""
        ended = torch.zeros(self.layout.n_contacts, rows.shape[1], device=self.device, dtype=self.dtype)
        if self.reference.clear_of_contacts(rows, torch.sqrt(w[0] * w[0] + w[1] * w[1]), self.dt_s):
            return self.reference.free_flight(rows, force), ended  # saves the detection ops of a calm period
        hook = self._substep_hook
        for s in range(self.scene.substeps):
            new, ended = self.reference.substep(rows, ended, force[:, s], None if noise is None else noise[s])
            if hook is not None:
                hook(s, rows, new, None if noise is None else noise[s])
            rows = new
        return rows, ended

    def _fused_period_impl(self, a: torch.Tensor, ang: torch.Tensor, omg: torch.Tensor, key0: torch.Tensor,
                           key1: torch.Tensor, k: torch.Tensor, ep: torch.Tensor,
                           rows: torch.Tensor) -> tuple[Any, ...]:
        """The prologue and every substep by the fused kernel (one pass of impulses): what torch.compile fuses.
        ``redo`` [N] marks the envs whose period the reference kernel must redo."""
        w, fuel, force, ang, omg, noise, flags = self._prologue_impl(a, ang, omg, key0, key1, k, ep)
        ended = torch.zeros(self.layout.n_contacts, rows.shape[1], device=rows.device, dtype=rows.dtype)
        redo = torch.zeros(rows.shape[1], device=rows.device, dtype=torch.bool)
        for s in range(self.scene.substeps):
            rows, ended, flagged = self._fused.substep(rows, ended, force[:, s], None if noise is None else noise[s])
            redo = redo | flagged
        return w, fuel, force, ang, omg, noise, flags, rows, ended, redo

    def _prologue_impl(self, a: torch.Tensor, ang: torch.Tensor, omg: torch.Tensor, key0: torch.Tensor,
                       key1: torch.Tensor, k: torch.Tensor, ep: torch.Tensor) -> tuple[Any, ...]:
        sc = self.scene
        w, fuel = episode.wrenches(a, self._limits, self.thrust_noise, (key0, key1), k, ep, self.dt_s)
        objects = ang.new_zeros(sc.n_bodies - sc.n_robots, ang.shape[1])
        dtorque = torch.cat((w[2] * self._inv_inertia * sc.dt_s, objects))
        starts, ang, omg = headings(ang, omg, dtorque, sc.substeps, sc.dt_s)
        force = world_forces(starts[:, : sc.n_robots], w[0], w[1])
        noise = None
        if self.impact_velocity_noise_mps > 0 and sc.robot_object_pairs:
            noise = episode.impact_noise(self.impact_velocity_noise_mps, len(sc.robot_object_pairs), sc.substeps,
                                         (key0, key1), k, ep, self.dtype)
        flags = torch.stack((~torch.isfinite(a).all(1), k >= self.horizon_steps))  # [2, N]
        return w, fuel, force, ang, omg, noise, flags

    def _epilogue_impl(self, rows: torch.Tensor, ang: torch.Tensor, omg: torch.Tensor, k: torch.Tensor,
                       monitor_state: MonitorState, potential: torch.Tensor, fuel_total: torch.Tensor,
                       fuel: torch.Tensor, ended: torch.Tensor, last_impact: torch.Tensor) -> tuple[Any, ...]:
        lay = self.layout
        B = self.n_bodies
        monitor_state, values = self.monitor.update_state(monitor_state, rows[: 2 * B].reshape(2, B, -1), k)
        terminated = k >= self.horizon_steps
        reward, estimate, potential = episode.reward(values, self.robustness_limit_m, self.reward_mode, potential,
                                                     terminated, fuel, self.fuel_penalty)
        open_contacts = rows[lay.pair_on.start: lay.static_on.stop].sum(0)
        impacts = ended.sum(0) + torch.where(terminated, open_contacts, 0.0)
        last_impact = torch.where(ended > 0.0, k, last_impact)
        obs = episode.observe(rows, ang, omg, k, self.horizon_steps, self._low, self._high)
        return (obs, reward, estimate, potential, fuel_total + fuel, monitor_state, terminated,
                impacts.round().to(torch.int64), last_impact, k)

    # ------------------------------------------------------------------------------------------- views
    def positions(self) -> torch.Tensor:
        """[2, B, N] body positions (m), the world's internal (batch-last) layout."""
        return self.rows[: 2 * self.n_bodies].reshape(2, self.n_bodies, self.num_envs)

    def body_state(self) -> torch.Tensor:
        """[N, B, 6] per body x, y (m), vx, vy (m/s), heading (rad), yaw rate (rad/s), in the world's dtype."""
        B = self.n_bodies
        r = self.rows
        return torch.stack((r[:B], r[B:2 * B], r[2 * B:3 * B], r[3 * B:4 * B], self.ang, self.omg)).permute(2, 1, 0)

    def observation(self) -> torch.Tensor:
        """[N, obs_size] float32: the central observation after the last reset or step."""
        if self._obs is None:
            raise ImpactEnvError("call reset() before reading observations")
        return self._obs

    def state(self) -> torch.Tensor:
        """[N, obs_size] float32 global state for centralised critics (the central observation)."""
        return self.observation()

    def agent_observations(self) -> torch.Tensor:
        """[N, R, obs_size] float32: robot r's observation has its own body first, then the others in order."""
        obs = self.observation()
        B, R = self.n_bodies, self.n_robots
        order = torch.tensor([episode.agent_order(B, r) for r in range(R)], device=self.device)
        blocks = obs[:, : OBS_PER_BODY * B].reshape(-1, B, OBS_PER_BODY)[:, order]  # [N, R, B, 7]
        time_left = obs[:, -1:].unsqueeze(1).expand(-1, R, 1)
        return torch.cat((blocks.reshape(-1, R, OBS_PER_BODY * B), time_left), dim=2)

    def close(self) -> None:
        """Close the renderers ``render_rgb`` opened."""
        for renderer in self._renderers.values():
            renderer.close()
        self._renderers.clear()

    def render_rgb(self, env_index: int, width_px: int = 600) -> np.ndarray:
        """A uint8 (H, W, 3) frame of env ``env_index``, drawn by :mod:`impact_env.transport.rendering`."""
        from impact_env.transport.batched.render import render_env

        return render_env(self, env_index, width_px)
