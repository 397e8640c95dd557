"""The PettingZoo environment: the library's own API tests, state, team reward, determinism."""

from __future__ import annotations

import pickle
import sys

import numpy as np
import pettingzoo
import pytest

import impact_env
from impact_env.transport import pettingzoo_env as transport_parallel


def test_parallel_api_test():
    from pettingzoo.test import parallel_api_test

    parallel_api_test(impact_env.parallel_env(scenario="throw_and_catch_exp"), num_cycles=300)


def test_aec_api_test():
    from pettingzoo.test import api_test

    api_test(impact_env.env(scenario="throw_and_catch_exp"), num_cycles=300)


def test_render_test():
    from pettingzoo.test import render_test

    render_test(lambda render_mode=None: impact_env.env(scenario="throw_and_catch_exp", render_mode=render_mode))


def test_max_cycles_test():
    """PettingZoo's test builds ``mod.parallel_env(max_cycles=...)`` with no scenario, which impact_env refuses
    on purpose (no silent default scenario): give it the module's entry points bound to one scenario."""
    from functools import partial
    from types import SimpleNamespace

    from pettingzoo.test import max_cycles_test

    mod = sys.modules[transport_parallel.__name__]
    bound = SimpleNamespace(**{name: partial(getattr(mod, name), scenario="throw_and_catch_exp")
                               for name in ("parallel_env", "env", "raw_env")})
    max_cycles_test(bound)


def test_no_silent_default_scenario():
    import gymnasium as gym

    from impact_env.errors import EnvConfigError

    for make in (lambda: gym.make("impact_env/Transport-v0"), lambda: gym.make("impact_env/Tether-v0"),
                 lambda: impact_env.transport_v0.TransportParallelEnv(),
                 lambda: impact_env.tether_v0.TetherParallelEnv()):  # the modules' entry points have defaults
        with pytest.raises(EnvConfigError, match="is required"):
            make()


def test_registry_and_spaces():
    from pettingzoo.env_registry.registration import parallel_registry

    assert "impact_env/transport-v0" in parallel_registry
    env = pettingzoo.make("parallel", "impact_env/transport-v0", scenario="corridor")
    obs, infos = env.reset(seed=0)
    assert env.agents == ["R1", "R2"]
    assert env.observation_space("R1") is env.observation_space("R1")
    assert env.observation_space("R1") == env.observation_space("R2")
    # own body first: R2's observation starts with R2's position, then R1's
    np.testing.assert_allclose(obs["R2"][0:2], [1.0, 9.0])
    np.testing.assert_allclose(obs["R2"][7:9], [1.0, 1.0])
    np.testing.assert_allclose(env.state()[0:2], [1.0, 1.0])
    assert env.state().shape == env.state_space.shape


def test_team_reward_and_joint_action_match_gym_env():
    par = impact_env.parallel_env(scenario="corridor")
    gym_env = impact_env.envs.TransportEnv("corridor")
    par.reset(seed=4)
    gym_env.reset(seed=4)
    rng = np.random.default_rng(1)
    for _ in range(200):
        a = rng.uniform(-1, 1, 6)
        obs, rewards, terms, truncs, infos = par.step({"R1": a[:3], "R2": a[3:]})
        gobs, greward, *_ = gym_env.step(a)
        assert rewards["R1"] == rewards["R2"] == greward
        np.testing.assert_array_equal(par.state(), gobs)


def test_parallel_determinism_over_300_steps():
    def run(seed):
        env = impact_env.parallel_env(scenario="corridor", thrust_noise=0.05, initial_position_noise_m=0.05)
        obs, _ = env.reset(seed=seed)
        rng = np.random.default_rng(0)
        out = [env.state()]
        for _ in range(300):
            env.step({a: rng.uniform(-1, 1, 3) for a in env.agents})
            out.append(env.state())
        return np.array(out)

    assert np.array_equal(run(5), run(5))
    assert not np.array_equal(run(5), run(6))


def test_pickle_and_episode_end():
    env = pickle.loads(pickle.dumps(impact_env.parallel_env(scenario="throw_and_catch_exp")))
    env.reset(seed=0)
    steps = 0
    while env.agents:
        _, _, terms, truncs, _ = env.step({a: np.zeros(3) for a in env.agents})
        steps += 1
    assert steps == 200 and all(terms.values()) and not any(truncs.values())
