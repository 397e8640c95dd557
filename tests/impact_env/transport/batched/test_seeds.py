"""An env's trajectory depends on its own seed only: not on the number of envs, its slot or the other envs."""

from __future__ import annotations

import numpy as np
import pytest

NOISE = {"thrust_noise": 0.05, "initial_position_noise_m": 0.05, "impact_velocity_noise_mps": 0.02}


def trajectory(num_envs: int, slot: int, seed: int, steps: int, name: str = "two_objects", **kwargs) -> list:
    """The observations and rewards of the env in ``slot``; the other envs get other seeds and actions."""
    import torch

    from impact_env.transport.batched import BatchedTransportWorld

    world = BatchedTransportWorld(name, num_envs, **NOISE, **kwargs)
    seeds = [1000 + i for i in range(num_envs)]
    seeds[slot] = seed
    obs = world.reset(seeds=seeds)
    out = [obs[slot].clone()]
    gen = torch.Generator().manual_seed(seed)
    others = torch.Generator().manual_seed(num_envs)
    for k in range(steps):
        a = torch.rand(num_envs, world.action_size, generator=others) * 2.4 - 1.2
        a[slot] = torch.rand(world.action_size, generator=gen) * 2.4 - 1.2
        obs, reward, _, _, info = world.step(a)
        out += [obs[slot].clone(), reward[slot].clone(), info["impacts"][slot].clone()]
        if k == steps // 2:  # the other envs restart mid-way: nothing changes for this one
            others_mask = torch.ones(num_envs, dtype=torch.bool)
            others_mask[slot] = False
            world.reset(mask=others_mask)
    return out


@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_slot_0_of_8_and_slot_5_of_64_give_the_same_trajectory(dtype):
    import torch

    dtype = getattr(torch, dtype)
    a = trajectory(8, 0, 42, 200, dtype=dtype)
    b = trajectory(64, 5, 42, 200, dtype=dtype)
    assert all(torch.equal(x, y) for x, y in zip(a, b))
    assert sum(int(x) for x in a[3::3]) > 0  # there were impacts (and so post-impact noise draws)


def test_another_seed_gives_another_trajectory():
    import torch

    a = trajectory(8, 0, 42, 20)
    b = trajectory(8, 0, 43, 20)
    assert not torch.equal(a[0], b[0])  # another start (initial-position noise)


def test_the_next_episode_continues_the_stream_of_the_seed():
    import torch

    from impact_env.transport.batched import BatchedTransportWorld

    world = BatchedTransportWorld("corridor", 2, **NOISE)
    first = world.reset(seeds=[7, 8])
    second = world.reset()
    assert world.episodes.tolist() == [1, 1]
    assert not torch.equal(first, second)
    other = BatchedTransportWorld("corridor", 3, **NOISE)
    other.reset(seeds=[9, 7, 8])
    again = other.reset(mask=torch.tensor([False, True, True]))
    assert torch.equal(again[1:], second)


def test_unseeded_envs_get_different_seeds():
    from impact_env.transport.batched import BatchedTransportWorld

    world = BatchedTransportWorld("corridor", 16, initial_position_noise_m=0.05)
    obs = world.reset()
    assert len(set(world.seeds.tolist())) == 16
    assert len({tuple(np.round(o.numpy(), 6)) for o in obs}) == 16


@pytest.mark.slow
def test_compiled_world_is_slot_independent_too():
    import torch

    a = trajectory(8, 0, 42, 100, compile=True)
    b = trajectory(64, 5, 42, 100, compile=True)
    assert all(torch.equal(x, y) for x, y in zip(a, b))
