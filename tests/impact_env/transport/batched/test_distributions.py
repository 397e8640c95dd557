"""Random-action episodes under 5 % thrust noise and 5 cm start noise: the final robustness of the batched
world and of the pymunk env have the same distribution (two-sample Kolmogorov-Smirnov test, alpha = 0.01).

The two draw their noise from different generators (Philox against numpy), so only distributions can
agree. 30 episodes per scenario in the default suite, 200 in the slow suite; the p-values are printed."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from impact_env.envs import TransportEnv
from impact_env.transport.batched import BatchedTransportWorld
from impact_env.transport.scenario import scenario_names

ALPHA = 0.01
NOISE = {"thrust_noise": 0.05, "initial_position_noise_m": 0.05}


def pymunk_finals(name: str, episodes: int) -> np.ndarray:
    env = TransportEnv(name, **NOISE)
    rng = np.random.default_rng(123)
    out = []
    for seed in range(episodes):
        env.reset(seed=seed)
        for _ in range(env.unwrapped.horizon_steps):
            _, _, terminated, _, info = env.step(rng.uniform(-1.0, 1.0, env.action_space.shape).astype(np.float32))
        assert terminated
        out.append(info["robustness"])
    return np.array(out)


def batched_finals(name: str, episodes: int) -> np.ndarray:
    world = BatchedTransportWorld(name, episodes, dtype=torch.float64, **NOISE)
    world.reset(seeds=10_000)
    gen = torch.Generator().manual_seed(456)
    for _ in range(world.horizon_steps):
        _, _, terminated, _, info = world.step(torch.rand(episodes, world.action_size, generator=gen) * 2 - 1)
    assert terminated.all()
    return info["robustness"].numpy()


def check(name: str, episodes: int) -> None:
    from scipy import stats  # imported when a test runs: collecting the suite does not need scipy.stats

    ref, got = pymunk_finals(name, episodes), batched_finals(name, episodes)
    result = stats.ks_2samp(ref, got)
    print(f"{name}: KS p = {result.pvalue:.3f} ({episodes} episodes each; mean final robustness "
          f"pymunk {ref.mean():.3f} m, batched {got.mean():.3f} m)")
    assert result.pvalue > ALPHA


@pytest.mark.parametrize("name", scenario_names())
def test_final_robustness_distribution_matches_pymunk(name):
    check(name, 30)


@pytest.mark.slow
@pytest.mark.parametrize("name", scenario_names())
def test_final_robustness_distribution_matches_pymunk_200_episodes(name):
    check(name, 200)
