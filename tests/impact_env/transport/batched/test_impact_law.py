"""Every isolated robot-object, object-wall and object-obstacle impact of random episodes obeys the law to
1e-6: the normal relative velocity after is -e times before (the paper's Eq. 5-7), the tangential parts keep
what they had plus the robot's thrust over the substep, and momentum changes by that thrust only."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import pytest

from impact_env.transport.scenario import load_scenario

if TYPE_CHECKING:
    from impact_env.transport.batched.scene import BoxShape


def closest_on_box(shape: BoxShape, p: np.ndarray) -> np.ndarray:
    return np.array([min(max(p[0], shape.x0), shape.x1), min(max(p[1], shape.y0), shape.y1)])


@pytest.mark.parametrize("name", [pytest.param("corridor", marks=pytest.mark.slow), "two_objects",
                                  "obstacle_avoidance"])
def test_every_isolated_impact_follows_the_law(name):
    import torch

    from impact_env.transport.batched.physics import ReferenceKernel, headings, world_forces
    from impact_env.transport.batched.scene import build_scene

    sc = load_scenario(name)
    scene = build_scene(sc)
    kernel = ReferenceKernel(scene, torch.device("cpu"), torch.float64)
    lay, B, R, N, dt = kernel.layout, scene.n_bodies, scene.n_robots, 64, scene.dt_s
    gen = torch.Generator().manual_seed(0)
    rows = torch.zeros(lay.n_rows, N, dtype=torch.float64)
    for b in range(B):
        rows[b], rows[B + b] = scene.position_m[b]
        rows[2 * B + b] = torch.randn(N, generator=gen, dtype=torch.float64) * 0.3  # everything moving
        rows[3 * B + b] = torch.randn(N, generator=gen, dtype=torch.float64) * 0.3
    ang = torch.zeros(B, N, dtype=torch.float64)
    omg = torch.zeros(B, N, dtype=torch.float64)
    limits = torch.tensor(scene.wrench_limits, dtype=torch.float64).T.reshape(3, R, 1)
    m = np.array(scene.mass_kg)
    e = scene.restitution
    checked = {"robot-object": 0, "object-wall": 0, "object-obstacle": 0}
    worst = 0.0
    for _ in range(300):
        w = (torch.rand(3, R, N, generator=gen, dtype=torch.float64) * 2 - 1) * limits
        dtorque = torch.cat((w[2] * torch.tensor(scene.inv_inertia[:R], dtype=torch.float64)[:, None] * dt,
                             torch.zeros(B - R, N, dtype=torch.float64)))
        starts, ang, omg = headings(ang, omg, dtorque, scene.substeps, dt)
        force = world_forces(starts[:, :R], w[0], w[1])
        for s in range(scene.substeps):
            before = rows.numpy().copy()
            rows, _ = kernel.substep(rows, torch.zeros(lay.n_contacts, N, dtype=torch.float64), force[:, s], None)
            after = rows.numpy()
            f = force[:, s].numpy()  # [2, R, N]
            on_before, on_after = before[lay.pair_on.start:] > 0.5, after[lay.pair_on.start:] > 0.5
            for env in np.flatnonzero((on_after & ~on_before).any(0)):
                count = np.zeros(B, dtype=int)  # contacts per body in this substep
                for p, (i, j) in enumerate(scene.pairs):
                    count[[i, j]] += on_after[p, env]
                statics = on_after[len(scene.pairs):, env].reshape(scene.n_static, B)
                count += statics.sum(0)
                pos = before[:2 * B, env].reshape(2, B).T + (before[2 * B:4 * B, env] + before[4 * B:6 * B, env]
                                                               ).reshape(2, B).T * dt
                v0 = before[2 * B:4 * B, env].reshape(2, B).T
                v1 = after[2 * B:4 * B, env].reshape(2, B).T
                dv_thrust = np.zeros((B, 2))
                dv_thrust[:R] = f[:, :, env].T / m[:R, None] * dt
                for p, (i, j) in enumerate(scene.pairs):
                    if on_after[p, env] and not on_before[p, env] and i < R <= j and count[i] == count[j] == 1:
                        n = (pos[j] - pos[i]) / np.linalg.norm(pos[j] - pos[i])
                        t = np.array([-n[1], n[0]])
                        err = [(v1[j] - v1[i]) @ n + e * ((v0[j] - v0[i]) @ n),
                               v1[i] @ t - (v0[i] + dv_thrust[i]) @ t, v1[j] @ t - v0[j] @ t,
                               *(m[i] * v1[i] + m[j] * v1[j] - m[i] * (v0[i] + dv_thrust[i]) - m[j] * v0[j])]
                        worst = max(worst, float(np.abs(err).max()))
                        checked["robot-object"] += 1
                for s_idx in range(scene.n_static):
                    for b in range(R, B):
                        if statics[s_idx, b] and not on_before[len(scene.pairs) + s_idx * B + b, env] and count[b] == 1:
                            if s_idx < 4:
                                n = np.array(((0, -1), (0, 1), (-1, 0), (1, 0))[s_idx], dtype=float)
                                kind = "object-wall"
                            else:
                                q = closest_on_box(scene.obstacles[s_idx - 4], pos[b])
                                n = (q - pos[b]) / np.linalg.norm(q - pos[b])
                                kind = "object-obstacle"
                            t = np.array([-n[1], n[0]])
                            err = [v1[b] @ n + e * (v0[b] @ n), (v1[b] - v0[b]) @ t]
                            worst = max(worst, float(np.abs(err).max()))
                            checked[kind] += 1
    print(f"{name}: impacts checked {checked}, largest deviation from the law {worst:.2e}")
    assert worst < 1e-6
    assert checked["robot-object"] >= 5 and checked["object-wall"] + checked["object-obstacle"] >= 5, checked
