"""Counter-based random numbers in torch ops: Philox-4x32-10, one stream per env seed.

An env of the batch must draw its noise as a function of its own seed and of where it is in its episode,
never of the batch size or of its slot. A ``torch.Generator`` per env would cost a Python call per env and
draw; Philox (Salmon, Moraes, Dror and Shaw, "Parallel random numbers: as easy as 1, 2, 3", SC 2011) maps a
128-bit counter and a 64-bit key to four random 32-bit words with integer multiplies and xors only, so every
draw of every env is one tensor expression: the key is the env's seed, the counter says which draw (step,
episode, purpose, index). The output is checked against the paper's known-answer vectors in the tests.

The 32-bit words live in int64 tensors. Each 32 x 32 -> 64-bit product is taken in 16-bit halves so that
no intermediate exceeds 2**49: signed int64 overflow is undefined behaviour in the C++ that torch.compile
generates, and the split costs a few integer ops.
"""

from __future__ import annotations

import math

import torch

_MASK32 = 0xFFFFFFFF
_M0, _M1 = 0xD2511F53, 0xCD9E8D57  # Philox-4x32 round multipliers
_W0, _W1 = 0x9E3779B9, 0xBB67AE85  # key schedule (Weyl) increments
ROUNDS = 10

# counter word 2: the purpose of a draw, so that two kinds of noise never share a stream
STREAM_START = 1  # initial-position noise (reset)
STREAM_THRUST = 2  # multiplicative thrust noise (every step)
STREAM_IMPACT = 3  # post-impact velocity noise (every step, one draw per substep and robot-object pair)
STREAM_SEED = 4  # seeds of episodes reset without a seed


def _mulhilo(m: int, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """High and low 32-bit words of the 64-bit product m * x (m a 32-bit constant, x 32-bit words)."""
    x_lo = x & 0xFFFF
    x_hi = x >> 16
    p_lo = x_lo * m  # < 2**48
    p_hi = x_hi * m  # < 2**48
    mid = p_lo + ((p_hi & 0xFFFF) << 16)  # < 2**49
    return (p_hi >> 16) + (mid >> 32), mid & _MASK32


def philox4x32(counter: tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor],
               key: tuple[torch.Tensor, torch.Tensor]) -> tuple[torch.Tensor, ...]:
    """Philox-4x32-10 of ``counter`` (4 words) under ``key`` (2 words): 4 random 32-bit words.

    Every argument is an int64 tensor of values in [0, 2**32) (broadcastable against each other); the
    outputs have the broadcast shape.
    """
    c0, c1, c2, c3 = counter
    k0, k1 = key
    for r in range(ROUNDS):
        if r:
            k0 = (k0 + _W0) & _MASK32
            k1 = (k1 + _W1) & _MASK32
        hi0, lo0 = _mulhilo(_M0, c0)
        hi1, lo1 = _mulhilo(_M1, c2)
        c0, c1, c2, c3 = hi1 ^ c1 ^ k0, lo1, hi0 ^ c3 ^ k1, lo0
    return c0, c1, c2, c3


def seed_key(seeds: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The Philox key (two 32-bit words) of int64 seeds in [0, 2**63)."""
    return seeds & _MASK32, (seeds >> 32) & _MASK32


def uniform_open(words: torch.Tensor, dtype: torch.dtype) -> torch.Tensor:
    """Uniform numbers in the open interval (0, 1) from 32-bit words: (2 * (w >> 9) + 1) / 2**24.

    23 random bits, so that the value is exact in float32 and float64 alike (a float32 and a float64 world
    draw the same numbers) and never 0 or 1 (the logarithm of Box-Muller stays finite).
    """
    return ((words >> 9) * 2 + 1).to(dtype) * (2.0 ** -24)


def normal_pairs(w0: torch.Tensor, w1: torch.Tensor, dtype: torch.dtype) -> tuple[torch.Tensor, torch.Tensor]:
    """Two independent standard normal samples from two words each (Box-Muller)."""
    radius = torch.sqrt(-2.0 * torch.log(uniform_open(w0, dtype)))
    angle = uniform_open(w1, dtype) * (2.0 * math.pi)
    return radius * torch.cos(angle), radius * torch.sin(angle)
