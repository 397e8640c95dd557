"""The env semantics around the physics, as pure tensor functions: the pymunk ``TransportCore``'s rules.

- :func:`wrenches`: actions in [-1, 1] clipped and scaled to the robots' limits, multiplicative thrust
  noise re-clipped to the limits, fuel (sum over robots of |F| times the control period, N s);
- :func:`impact_noise`: the post-impact velocity errors every robot-object contact of this period would get
  if it ended in a given substep (uniform in [-noise, noise] per axis);
- :func:`observe`: per body (x, y, vx, vy, cos, sin, omega), then the fraction of time left, clipped to the
  observation bounds, float32;
- :func:`reward`: dense / sparse / conjuncts, minus the fuel penalty, robustness clipped to +- the limit.

Every random draw is a Philox block keyed by the env's seed with counter (step, episode, stream, block),
so it depends on the env's own seed and position in its episode only. They are kept free of
data-dependent Python so that torch.compile can fuse them.
"""

from __future__ import annotations

import torch

from impact_env.transport.batched import philox


def _normals(key: tuple[torch.Tensor, torch.Tensor], step: torch.Tensor, episode: torch.Tensor, stream: int,
             count: int, dtype: torch.dtype) -> torch.Tensor:
    """[count, N] standard normal draws: Box-Muller on Philox blocks (4 normals per block)."""
    blocks = torch.arange((count + 3) // 4, device=step.device).reshape(-1, 1)
    w = philox.philox4x32((step, episode, torch.full_like(blocks, stream), blocks), key)
    z0, z1 = philox.normal_pairs(w[0], w[1], dtype)
    z2, z3 = philox.normal_pairs(w[2], w[3], dtype)
    return torch.stack((z0, z1, z2, z3), dim=1).reshape(-1, step.shape[0])[:count]


def _uniforms(key: tuple[torch.Tensor, torch.Tensor], step: torch.Tensor, episode: torch.Tensor, stream: int,
              count: int, dtype: torch.dtype) -> torch.Tensor:
    """[count, N] uniform draws in (0, 1) (4 per Philox block)."""
    blocks = torch.arange((count + 3) // 4, device=step.device).reshape(-1, 1)
    w = philox.philox4x32((step, episode, torch.full_like(blocks, stream), blocks), key)
    return philox.uniform_open(torch.stack(w, dim=1).reshape(-1, step.shape[0])[:count], dtype)


def wrenches(actions: torch.Tensor, limits: torch.Tensor, thrust_noise: float, key: tuple[torch.Tensor, torch.Tensor],
             step: torch.Tensor, episode: torch.Tensor, dt_s: float) -> tuple[torch.Tensor, torch.Tensor]:
    """Body-frame wrenches [3, R, N] (N, N, N m) and this step's fuel [N] (N s) from actions [N, 3R].

    ``limits`` is [3, R, 1]: Fx, Fy and torque limits per robot.
    """
    n, dims = actions.shape
    # batch-last and contiguous over the envs, so that what follows runs as vectorised loops
    a = torch.clamp(actions, -1.0, 1.0).t().contiguous().reshape(dims // 3, 3, n).transpose(0, 1)
    w = a * limits
    if thrust_noise > 0.0:
        z = _normals(key, step, episode, philox.STREAM_THRUST, dims, w.dtype).reshape(dims // 3, 3, n)
        w = w * (1.0 + thrust_noise * z.permute(1, 0, 2))
        w = torch.minimum(torch.maximum(w, -limits), limits)
    fuel = torch.sqrt(w[0, 0] * w[0, 0] + w[1, 0] * w[1, 0])
    for r in range(1, dims // 3):
        fuel = fuel + torch.sqrt(w[0, r] * w[0, r] + w[1, r] * w[1, r])
    return w, dt_s * fuel


def impact_noise(noise_mps: float, n_pairs: int, substeps: int, key: tuple[torch.Tensor, torch.Tensor],
                 step: torch.Tensor, episode: torch.Tensor, dtype: torch.dtype) -> torch.Tensor:
    """[substeps, n_pairs, 2, N] uniform velocity errors in [-noise, noise] (m/s)."""
    u = _uniforms(key, step, episode, philox.STREAM_IMPACT, substeps * n_pairs * 2, dtype)
    return ((2.0 * noise_mps) * u - noise_mps).reshape(substeps, n_pairs, 2, step.shape[0])


def observe(rows: torch.Tensor, ang: torch.Tensor, omg: torch.Tensor, step: torch.Tensor, horizon_steps: int,
            low: torch.Tensor, high: torch.Tensor) -> torch.Tensor:
    """[N, 7 B + 1] float32 observations (the layout of ``TransportCore.observation``)."""
    B, N = ang.shape
    per_body = torch.stack((rows[:B], rows[B:2 * B], rows[2 * B:3 * B], rows[3 * B:4 * B], torch.cos(ang),
                            torch.sin(ang), omg), dim=1).reshape(7 * B, N)
    left = torch.clamp(1.0 - step.to(torch.float64) / horizon_steps, min=0.0)  # float64 as TransportCore
    obs = torch.cat((per_body.to(torch.float32), left.to(torch.float32).unsqueeze(0))).T
    return torch.minimum(torch.maximum(obs, low), high)


def agent_order(n_bodies: int, robot: int) -> list[int]:
    """Body order of a robot's observation: its own body first, then the others in scenario order."""
    return [robot] + [i for i in range(n_bodies) if i != robot]


def reward(values: torch.Tensor, limit_m: float, mode: str, prev: torch.Tensor, terminated: torch.Tensor,
           fuel: torch.Tensor, fuel_penalty: float) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """(reward [N], robustness estimate [N] (m), new potential [N]) from the monitor's values [F, N].

    values[0] is the task; values[1:] its conjuncts (``mode == "conjuncts"``).
    """
    estimate = torch.clamp(values[0], -limit_m, limit_m)
    potential = prev
    if mode == "dense":
        r = estimate - prev
        potential = estimate
    elif mode == "conjuncts":
        parts = torch.clamp(values[1:], -limit_m, limit_m)
        total = parts[0]
        for p in parts[1:]:
            total = total + p
        potential = total / parts.shape[0]
        r = potential - prev
    else:
        r = torch.where(terminated, estimate, 0.0)
    return r - fuel_penalty * fuel, estimate, potential

