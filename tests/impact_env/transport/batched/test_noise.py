"""The three noises of the batched world: start positions, thrust and post-impact velocity errors."""

from __future__ import annotations

import math

import numpy as np
import pytest

from impact_env.transport.scenario import load_scenario, scenario_from_dict
from tests.helpers import two_body_dict


def test_starts_are_uniform_in_the_noise_disc_and_clear():
    import torch
    from scipy import stats  # imported when the test runs, not while the suite is collected

    from impact_env.transport.batched import BatchedTransportWorld

    sc = load_scenario("two_objects")
    noise = 0.3
    world = BatchedTransportWorld(sc, 4000, dtype=torch.float64, initial_position_noise_m=noise)
    world.reset(seeds=0)
    state = world.body_state().numpy()
    R = len(sc.robots)
    for j, body in enumerate(sc.objects):
        offset = state[:, R + j, :2] - np.array(body.position_m)
        r2 = (offset ** 2).sum(1) / noise ** 2
        assert r2.max() <= 1.0
    # robots are never moved; no two discs overlap and none leaves the box or enters an obstacle
    np.testing.assert_array_equal(state[:, :R, :2], np.broadcast_to([b.position_m for b in sc.robots], (4000, R, 2)))
    for i, a in enumerate(sc.bodies):
        for k in range(i + 1, len(sc.bodies)):
            gap = np.linalg.norm(state[:, i, :2] - state[:, k, :2], axis=1) - a.radius_m - sc.bodies[k].radius_m
            assert gap.min() >= 0.0
        for obstacle in sc.obstacles:
            assert (obstacle.polygon.signed_distance(state[:, i, :2]) <= -a.radius_m).all()
    # O2 is far from everything at this radius: its starts are uniform over the disc (r^2 uniform, angle uniform)
    offset = state[:, R + 1, :2] - np.array(sc.objects[1].position_m)
    assert stats.kstest((offset ** 2).sum(1) / noise ** 2, "uniform").pvalue > 0.01
    assert stats.kstest(np.arctan2(offset[:, 1], offset[:, 0]), "uniform", args=(-math.pi, 2 * math.pi)).pvalue > 0.01


def test_starts_next_to_an_obstacle_are_redrawn():
    import torch

    from impact_env.transport.batched import BatchedTransportWorld

    data = two_body_dict(object_pos=(4.0, 5.0))
    data["obstacles"] = [{"name": "block", "box": [4.25, 6.0, 3.0, 7.0]}]  # 5 cm from the object's disc
    sc = scenario_from_dict(data)
    world = BatchedTransportWorld(sc, 2000, dtype=torch.float64, initial_position_noise_m=0.2)
    world.reset(seeds=1)
    x = world.body_state()[:, 1, 0].numpy()
    assert x.max() <= 4.05 + 1e-12  # the disc (r = 0.2) never reaches the block at x = 4.25
    assert (x > 4.0).mean() > 0.1 and x.min() < 3.85  # but the clear part of the disc is used


def test_thrust_noise_is_multiplicative_and_clipped_to_the_limits():
    import torch
    from scipy import stats  # imported when the test runs, not while the suite is collected

    from impact_env.transport.batched import episode

    limits = torch.tensor([2.8, 2.8, 0.2], dtype=torch.float64).reshape(3, 1, 1)
    n = 20000
    seeds = torch.arange(n)
    key = (seeds & 0xFFFFFFFF, seeds >> 32)
    zeros = torch.zeros(n, dtype=torch.int64)
    half = torch.full((n, 3), 0.5, dtype=torch.float64)
    w, fuel = episode.wrenches(half, limits, 0.1, key, zeros, zeros, 0.1)
    z = (w[:, 0] / (0.5 * limits[:, 0]) - 1.0) / 0.1  # the standard normal draws
    assert stats.kstest(z.flatten().numpy(), "norm").pvalue > 0.01
    full = torch.ones(n, 3, dtype=torch.float64)
    w, _ = episode.wrenches(full, limits, 0.5, key, zeros, zeros, 0.1)
    assert (w.abs() <= limits).all() and (w == limits).float().mean() > 0.4  # re-clipped, often at the limit
    w, _ = episode.wrenches(half, limits, 0.1, key, zeros + 1, zeros, 0.1)  # the next step draws anew
    assert not torch.equal(w[:, 0], 0.5 * limits[:, 0] * (1 + 0.1 * z))


def test_post_impact_velocity_error_is_uniform_on_top_of_eq5():
    """Head-on robot-object impacts in 2000 envs: the object leaves with Eq. (5) plus a uniform draw per axis
    in [-noise, noise]; the robot's own velocity is Eq. (5) unchanged."""
    import torch
    from scipy import stats  # imported when the test runs, not while the suite is collected

    from impact_env.transport.batched import BatchedTransportWorld

    noise, e = 0.02, 0.5
    sc = scenario_from_dict(two_body_dict(e=e, robot_vel=(0.3, 0.0), control_period_s=0.01, substeps=1))
    world = BatchedTransportWorld(sc, 2000, dtype=torch.float64, impact_velocity_noise_mps=noise)
    world.reset(seeds=0)
    for _ in range(600):
        _, _, _, _, info = world.step(torch.zeros(2000, 3))
        if bool((info["impacts"] > 0).all()):
            break
    assert bool((info["impacts"] == 1).all())  # every env's impact ended in the same substep
    v = world.body_state()[:, :, 2:4].numpy()
    vr, vo = 0.5 * (1 - e) * 0.3, 0.5 * (1 + e) * 0.3
    np.testing.assert_allclose(v[:, 0], np.broadcast_to([vr, 0.0], (2000, 2)), atol=1e-12)
    errors = v[:, 1] - [vo, 0.0]
    assert np.abs(errors).max() <= noise + 1e-12
    for axis in range(2):
        assert stats.kstest(errors[:, axis], "uniform", args=(-noise, 2 * noise)).pvalue > 0.01


def test_wall_contacts_get_no_post_impact_error():
    import torch

    from impact_env.transport.batched import BatchedTransportWorld

    sc = scenario_from_dict(two_body_dict(e=0.75, robot_pos=(2.0, 8.0), robot_vel=(0.0, 0.0), object_pos=(9.0, 5.0),
                                          object_vel=(0.4, 0.0), control_period_s=0.01, substeps=1))
    world = BatchedTransportWorld(sc, 16, dtype=torch.float64, impact_velocity_noise_mps=0.05)
    world.reset(seeds=0)
    for _ in range(1000):
        _, _, _, _, info = world.step(torch.zeros(16, 3))
        if bool(info["impacts"].any()):
            break
    np.testing.assert_allclose(world.body_state()[:, 1, 2:4].numpy(), np.broadcast_to([-0.3, 0.0], (16, 2)),
                               atol=1e-12)


@pytest.mark.parametrize("noise", [0.0, 0.05])
def test_noise_options_leave_a_noiseless_world_exact(noise):
    """Thrust noise 0 draws nothing: the world is the noiseless one, whatever the seed."""
    import torch

    from impact_env.transport.batched import BatchedTransportWorld

    a, b = (BatchedTransportWorld("corridor", 2, impact_velocity_noise_mps=noise) for _ in range(2))
    a.reset(seeds=[1, 2])
    b.reset(seeds=[3, 4])
    act = torch.full((2, 6), 0.7)
    for _ in range(20):
        oa = a.step(act)[0]
        ob = b.step(act)[0]
    assert torch.equal(oa, ob)
