"""Initial-position noise for a batch, with the placement rules of :mod:`impact_env.transport.starts`.

Each object, in scenario order, starts uniformly within ``noise_m`` of its scenario position (radius
noise * sqrt(u1), angle 2 pi u2, as the pymunk environments draw it); a start whose disc would leave the
world box, overlap an obstacle or overlap another body (a robot, an object already placed, or an object not
placed yet at its scenario position) is rejected and the next candidate of the env's stream is taken. The
candidates are Philox draws keyed by the env's seed and numbered (candidate, episode, object), so the
accepted start is the first clear candidate: exactly rejection sampling, computed for many candidates at
once. The pymunk environments draw from numpy's generator instead, so the starts have the same
distribution, not the same values. The radius has been checked by
:func:`impact_env.transport.starts.check_noise` (at least 5 % of the candidates are clear).
"""

from __future__ import annotations

import math

import torch

from impact_env.errors import EnvConfigError
from impact_env.transport.batched import philox
from impact_env.transport.batched.monitor import signed_distance
from impact_env.transport.scenario import Scenario
from impact_env.transport.starts import MAX_DRAWS

CHUNK = 32  # candidates drawn at once per object and env; P(all 32 rejected) < 0.95**32 = 19 %, rarely more


def _clear(scenario: Scenario, radius_m: float, x: torch.Tensor, y: torch.Tensor,
           others: list[tuple[torch.Tensor | float, torch.Tensor | float, float]]) -> torch.Tensor:
    xmin, xmax, ymin, ymax = scenario.world_box
    ok = (x >= xmin + radius_m) & (x <= xmax - radius_m) & (y >= ymin + radius_m) & (y <= ymax - radius_m)
    for obstacle in scenario.obstacles:
        ok = ok & (signed_distance(obstacle.polygon, x, y) <= -radius_m)
    for ox, oy, orad in others:
        ok = ok & (torch.sqrt((x - ox) ** 2 + (y - oy) ** 2) >= radius_m + orad)
    return ok


def draw_object_starts(scenario: Scenario, noise_m: float, seeds: torch.Tensor,
                       episodes: torch.Tensor) -> torch.Tensor:
    """[2, n_objects, M] starts (m, float64) of the objects of M envs with int64 ``seeds`` and ``episodes``."""
    device = seeds.device
    key = philox.seed_key(seeds)
    M = seeds.shape[0]
    placed: list[tuple[torch.Tensor | float, torch.Tensor | float, float]] = [
        (b.position_m[0], b.position_m[1], b.radius_m) for b in scenario.robots]
    out = []
    n_robots = len(scenario.robots)
    for index, body in enumerate(scenario.objects):
        pending = [(b.position_m[0], b.position_m[1], b.radius_m) for b in scenario.objects[index + 1:]]
        x = torch.full((M,), body.position_m[0], dtype=torch.float64, device=device)
        y = torch.full((M,), body.position_m[1], dtype=torch.float64, device=device)
        done = torch.zeros(M, dtype=torch.bool, device=device)
        for first in range(0, MAX_DRAWS, CHUNK):
            todo = (~done).nonzero().squeeze(1)
            if todo.numel() == 0:
                break
            j = torch.arange(first, min(first + CHUNK, MAX_DRAWS), device=device).reshape(-1, 1)
            words = philox.philox4x32((j, episodes[todo], torch.full_like(j, philox.STREAM_START),
                                       torch.full_like(j, n_robots + index)), (key[0][todo], key[1][todo]))
            radius = noise_m * torch.sqrt(philox.uniform_open(words[0], torch.float64))
            angle = philox.uniform_open(words[1], torch.float64) * (2.0 * math.pi)
            cx = body.position_m[0] + radius * torch.cos(angle)  # [candidates, len(todo)]
            cy = body.position_m[1] + radius * torch.sin(angle)
            others = [(o[0] if isinstance(o[0], float) else o[0][todo], o[1] if isinstance(o[1], float) else o[1][todo],
                       o[2]) for o in placed + pending]
            clear = _clear(scenario, body.radius_m, cx, cy, others)
            found = clear.any(0)
            pick = clear.to(torch.int8).argmax(0)  # the first clear candidate
            cols = torch.arange(todo.numel(), device=device)
            x[todo] = torch.where(found, cx[pick, cols], x[todo])
            y[todo] = torch.where(found, cy[pick, cols], y[todo])
            done[todo] = found
        if not bool(done.all()):
            raise EnvConfigError(f"initial_position_noise_m = {noise_m:g} m: no clear start for {body.name} in "
                                 f"{MAX_DRAWS} draws; use a smaller radius")
        placed.append((x, y, body.radius_m))
        out.append(torch.stack((x, y)))
    return torch.stack(out, dim=1) if out else torch.zeros(2, 0, M, dtype=torch.float64, device=device)
