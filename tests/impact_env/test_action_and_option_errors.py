"""Malformed actions and environment options (issue 11): typed errors in both environments, and
initial-position noise that respects the placement rules."""

from __future__ import annotations

import math

import numpy as np
import pytest

import impact_env
from impact_env.envs import TransportEnv
from impact_env.errors import ActionError, EnvConfigError


@pytest.fixture
def gym_env():
    env = TransportEnv("corridor")
    env.reset(seed=0)
    return env


@pytest.fixture
def pz_env():
    env = impact_env.parallel_env(scenario="corridor")
    env.reset(seed=0)
    return env


@pytest.mark.parametrize("action, message", [
    ([[1, 2, 3], [4, 5]], "ragged"),
    (np.zeros((3, 2)), r"shape \(6,\) or \(2, 3\).*got shape \(3, 2\)"),
    (np.zeros((1, 6)), r"got shape \(1, 6\)"),
    ("abcdef", "got str"),
    ("123456", "got str"),
    (None, "got NoneType"),
    ({"R1": [0, 0, 0]}, "got dict"),
    ([0, 0, 0, 0, 0, "x"], "only numbers"),
    ([True] * 6, "only numbers"),
    ([1j] * 6, "only numbers"),
    ([10 ** 400] * 6, "too large for a float"),
    ([0, 0, 0, 0, 0, None], "only numbers"),
])
def test_gym_env_rejects_malformed_actions(gym_env, action, message):
    with pytest.raises(ActionError, match=message):
        gym_env.step(action)


def test_gym_env_still_takes_both_documented_shapes_and_plain_lists(gym_env):
    gym_env.step(np.zeros(6, dtype=np.float32))
    gym_env.step(np.zeros((2, 3)))
    gym_env.step([[0, 0, 0], [0, 0, 0]])
    gym_env.step((0.0, 0.5, 0, 1, 0, 0))
    gym_env.step(np.ones(6, dtype=np.int64))
    assert gym_env.core.last_wrenches[0] == pytest.approx((2.8, 2.8, 0.2))


@pytest.mark.parametrize("actions, message", [
    ({"R1": "abc"}, r"actions\['R1'\] must be 3 numbers .* got str"),
    ({"R1": [1, 2]}, r"actions\['R1'\] must be 3 numbers .*got shape \(2,\)"),
    ({"R1": [[1, 2, 3]]}, r"got shape \(1, 3\)"),
    ({"R1": [[1, 2, 3], [4]]}, "ragged"),
    ({"R9": [0, 0, 0]}, r"unknown agents \[\"'R9'\"\]"),
    ({0: [0, 0, 0]}, "unknown agents"),
    ([0, 0, 0, 0, 0, 0], "must be a dict"),
    ({"R1": [math.nan, 0, 0]}, "NaN"),
])
def test_pettingzoo_env_rejects_malformed_actions(pz_env, actions, message):
    with pytest.raises(ActionError, match=message):
        pz_env.step(actions)


def test_pettingzoo_missing_and_none_actions_are_zero_thrust(pz_env):
    pz_env.step({"R1": None})
    assert pz_env.core.last_wrenches == [(0.0, 0.0, 0.0)] * 2


@pytest.mark.parametrize("kwargs, message", [
    ({"render_mode": "png"}, "render_mode"),
    ({"render_width_px": 10 ** 9}, "render_width_px"),
    ({"render_width_px": True}, "render_width_px"),
    ({"initial_position_noise_m": 1e300}, r"only 0\.0% of the starts"),
    ({"initial_position_noise_m": math.nan}, "initial_position_noise_m"),
    ({"thrust_noise": math.inf}, "thrust_noise"),
    ({"thrust_noise": 1e308}, r"thrust_noise must be a finite number in \[0, 10\]"),  # found by the fuzzers
    ({"fuel_penalty": 1e300}, r"fuel_penalty must be a finite number in \[0, 1e\+06\]"),
])
def test_bad_options_are_env_config_errors(kwargs, message):
    with pytest.raises(EnvConfigError, match=message):
        TransportEnv("corridor", **kwargs)
    with pytest.raises(EnvConfigError, match=message):
        impact_env.parallel_env(scenario="corridor", **kwargs)


def test_pettingzoo_max_cycles_is_an_env_config_error():
    with pytest.raises(EnvConfigError, match="max_cycles"):
        impact_env.parallel_env(scenario="corridor", max_cycles=0)


def test_large_initial_noise_never_starts_an_object_inside_a_wall():
    """The corridor's object is 1 m from each wall: 1.5 m of noise used to put it in a wall in 11 of 30 seeds."""
    scenario = TransportEnv("corridor").scenario
    robots = [(b.position_m, b.radius_m) for b in scenario.robots]
    for seed in range(30):
        env = TransportEnv("corridor", initial_position_noise_m=1.5)
        env.reset(seed=seed)
        x, y = env.core._state[2][:2]
        r = scenario.objects[0].radius_m
        assert 0.0 + r <= x <= 2.0 - r and 0.0 + r <= y <= 10.0 - r
        assert math.dist((x, y), scenario.objects[0].position_m) <= 1.5
        for (rx, ry), rr in robots:
            assert math.dist((x, y), (rx, ry)) >= r + rr


def test_noisy_starts_are_deterministic_in_the_seed():
    a = TransportEnv("corridor", initial_position_noise_m=1.5)
    b = TransportEnv("corridor", initial_position_noise_m=1.5)
    for seed in (3, 7):
        a.reset(seed=seed)
        b.reset(seed=seed)
        assert a.core._state == b.core._state


def test_deeply_nested_and_huge_actions_are_action_errors(gym_env):
    deep = [0.0] * 6
    for _ in range(5000):
        deep = [deep]
    with pytest.raises(ActionError, match="a list, which is ragged or nested too deeply"):
        gym_env.step(deep)
    with pytest.raises(ActionError, match="too large for a float"):
        gym_env.step([10 ** 5000] * 6)
