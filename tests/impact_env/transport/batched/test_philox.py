"""Philox-4x32-10 against the known-answer vectors of Salmon et al. (Random123's kat_vectors), and the
uniform and normal transforms built on it."""

from __future__ import annotations

import math

import numpy as np
import pytest

KAT = [  # (counter, key, output), philox4x32_10
    ((0, 0, 0, 0), (0, 0), (0x6627E8D5, 0xE169C58D, 0xBC57AC4C, 0x9B00DBD8)),
    ((0xFFFFFFFF,) * 4, (0xFFFFFFFF,) * 2, (0x408F276D, 0x41C83B0E, 0xA20BC7C6, 0x6D5451FD)),
    ((0x243F6A88, 0x85A308D3, 0x13198A2E, 0x03707344), (0xA4093822, 0x299F31D0),
     (0xD16CFE09, 0x94FDCCEB, 0x5001E420, 0x24126EA1)),
]


@pytest.mark.parametrize("counter,key,expected", KAT)
def test_philox_matches_the_known_answers(counter, key, expected):
    import torch

    from impact_env.transport.batched import philox

    t = [torch.tensor([v], dtype=torch.int64) for v in counter + key]
    out = philox.philox4x32(tuple(t[:4]), tuple(t[4:]))
    assert tuple(int(w) for w in out) == expected


def test_philox_broadcasts_and_each_lane_is_its_own_counter():
    import torch

    from impact_env.transport.batched import philox

    c = torch.arange(8, dtype=torch.int64)
    z = torch.zeros(8, dtype=torch.int64)
    batch = philox.philox4x32((c, z, z, z), (z + 7, z))
    for i in range(8):
        one = philox.philox4x32(tuple(torch.tensor([v]) for v in (i, 0, 0, 0)), (torch.tensor([7]), torch.tensor([0])))
        assert [int(w[i]) for w in batch] == [int(w) for w in one]


def test_uniforms_are_open_exact_in_float32_and_uniform():
    import torch

    from impact_env.transport.batched import philox

    words = torch.tensor([0, 1, 511, 512, 2 ** 32 - 1], dtype=torch.int64)
    u32 = philox.uniform_open(words, torch.float32)
    u64 = philox.uniform_open(words, torch.float64)
    assert torch.equal(u32.double(), u64)  # the same numbers in both dtypes
    assert float(u64.min()) > 0.0 and float(u64.max()) < 1.0
    assert float(u64[0]) == 2.0 ** -24 and float(u64[-1]) == 1.0 - 2.0 ** -24
    c = torch.arange(20000, dtype=torch.int64)
    z = torch.zeros_like(c)
    u = philox.uniform_open(philox.philox4x32((c, z, z, z), (z, z))[0], torch.float64).numpy()
    from scipy import stats

    assert stats.kstest(u, "uniform").pvalue > 0.01


def test_normal_pairs_are_standard_normal():
    import torch

    from impact_env.transport.batched import philox

    c = torch.arange(20000, dtype=torch.int64)
    z = torch.zeros_like(c)
    w = philox.philox4x32((c, z, z, z), (z + 3, z))
    a, b = philox.normal_pairs(w[0], w[1], torch.float64)
    samples = np.concatenate([a.numpy(), b.numpy()])
    from scipy import stats

    assert stats.kstest(samples, "norm").pvalue > 0.01
    assert abs(float(np.corrcoef(a.numpy(), b.numpy())[0, 1])) < 4.0 / math.sqrt(len(a))


def test_seed_key_splits_a_63_bit_seed():
    import torch

    from impact_env.transport.batched import philox

    seeds = torch.tensor([0, 1, 2 ** 32, 2 ** 63 - 1], dtype=torch.int64)
    k0, k1 = philox.seed_key(seeds)
    assert k0.tolist() == [0, 1, 0, 2 ** 32 - 1] and k1.tolist() == [0, 0, 1, 2 ** 31 - 1]
