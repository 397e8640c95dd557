"""Every shipped scenario and station has an id with ``max_episode_steps``; the generic ids take theirs from the
file they are made with; PettingZoo's own test suite runs on both versioned modules as they are (issue 24)."""

from __future__ import annotations

import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import impact_env
from impact_env import (
    GYM_IDS,
    TETHER_GYM_IDS,
    TETHER_GYM_IDS_V0,
    scenario_names,
    station_names,
    tether_v0,
    tether_v1,
    transport_v0,
)
from impact_env.errors import EnvConfigError

SCENARIOS = Path(impact_env.__file__).parent / "transport" / "scenarios"
NEW_IDS = {"impact_env/Relay-v0": "relay", "impact_env/TwoObjects-v0": "two_objects",
           "impact_env/PingPongStop-v0": "ping_pong_stop", "impact_env/LongThrowTrim-v0": "long_throw_trim",
           "impact_env/NarrowGap-v0": "narrow_gap", "impact_env/OneRobotTwoObjects-v0": "one_robot_two_objects",
           "impact_env/TimedVisits-v0": "timed_visits", "impact_env/WallStart-v0": "wall_start",
           "impact_env/FourRobots-v0": "four_robots", "impact_env/HeldDrift-v0": "held_drift"}


def test_every_shipped_scenario_and_station_has_an_id():
    assert sorted(GYM_IDS.values()) == sorted(scenario_names())
    assert sorted(TETHER_GYM_IDS.values()) == sorted(station_names())
    assert NEW_IDS.items() <= GYM_IDS.items()


@pytest.mark.parametrize("env_id", sorted(NEW_IDS))
def test_the_new_ids_carry_their_horizon(env_id):
    spec = gym.spec(env_id)
    env = gym.make(env_id)
    assert spec.max_episode_steps == env.spec.max_episode_steps == env.unwrapped.horizon_steps > 0
    assert env.unwrapped.scenario.name == NEW_IDS[env_id]
    obs, _ = env.reset(seed=0)
    assert obs in env.observation_space
    env.close()


@pytest.mark.parametrize("kwargs", [{"scenario": "relay"}, {"scenario": str(SCENARIOS / "two_objects.toml")},
                                    {"scenario": impact_env.load_scenario("ping_pong_stop")}],
                         ids=["name", "path", "Scenario"])
def test_transport_v0_takes_max_episode_steps_from_its_file(kwargs):
    env = gym.make("impact_env/Transport-v0", **kwargs)
    assert env.spec.max_episode_steps == env.unwrapped.horizon_steps
    again = gym.make(env.spec)  # a spec read back from a made env makes the same env
    assert again.spec.max_episode_steps == env.spec.max_episode_steps
    assert again.unwrapped.scenario.name == env.unwrapped.scenario.name


def test_a_scenario_of_ones_own_gets_its_horizon(tmp_path):
    text = (SCENARIOS / "throw_and_catch_exp.toml").read_text()
    own = tmp_path / "short.toml"
    own.write_text(text.replace('name = "throw_and_catch_exp"', 'name = "short"', 1))
    env = gym.make("impact_env/Transport-v0", scenario=str(own))
    env.reset(seed=0)
    zero = np.zeros(env.action_space.shape, dtype=np.float32)
    steps = 0
    while True:
        _, _, terminated, truncated, _ = env.step(zero)
        steps += 1
        if terminated or truncated:
            break
    assert steps == env.spec.max_episode_steps == env.unwrapped.horizon_steps and terminated and truncated


@pytest.mark.parametrize("version, ids", [("v1", TETHER_GYM_IDS), ("v0", TETHER_GYM_IDS_V0)])
@pytest.mark.parametrize("station", ["L", "iss_chain"])
def test_tether_ids_take_max_episode_steps_from_their_file(station, version, ids):
    stations = Path(impact_env.__file__).parent / "tether" / "stations"
    for given in (station, str(stations / f"{station}.toml")):
        env = gym.make(f"impact_env/Tether-{version}", station=given)
        assert env.unwrapped.version == int(version[1])
        assert env.spec.max_episode_steps == env.unwrapped.horizon_steps
        assert env.spec.max_episode_steps == gym.spec(next(i for i, s in ids.items()
                                                           if s == station)).max_episode_steps


def test_a_smaller_max_episode_steps_still_cuts_earlier():
    env = gym.make("impact_env/Transport-v0", scenario="corridor", max_episode_steps=5)
    env.reset(seed=0)
    flags = [env.step(env.action_space.sample())[2:4] for _ in range(5)]
    assert flags[-1] == (False, True) and all(f == (False, False) for f in flags[:-1])
    assert env.spec.max_episode_steps == 5


def test_the_generic_ids_still_need_their_file_and_pass_the_checkers():
    from gymnasium.utils.env_checker import check_env

    with pytest.raises(EnvConfigError, match="scenario= is required"):
        gym.make("impact_env/Transport-v0")
    for version in ("v1", "v0"):
        with pytest.raises(EnvConfigError, match="station= is required"):
            gym.make(f"impact_env/Tether-{version}")
    check_env(gym.make("impact_env/Transport-v0", scenario="relay").unwrapped, skip_render_check=True)
    sb3 = pytest.importorskip("stable_baselines3.common.env_checker")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sb3.check_env(gym.make("impact_env/Transport-v0", scenario="two_objects"))


@pytest.mark.parametrize("module", [transport_v0, tether_v1, tether_v0], ids=["transport_v0", "tether_v1", "tether_v0"])
def test_pettingzoo_suite_on_the_modules_as_they_are(module):
    from pettingzoo.test import api_test, max_cycles_test, parallel_api_test

    max_cycles_test(module)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # api_test's advice on agent names (see the environment pages)
        api_test(module.env(), num_cycles=30)
        parallel_api_test(module.parallel_env(), num_cycles=30)


def test_module_defaults_are_the_documented_ones():
    assert transport_v0.parallel_env().scenario.name == "corridor"
    assert tether_v1.parallel_env().station.name == tether_v0.parallel_env().station.name == "L"
    assert tether_v1.parallel_env().possible_agents == ["R1", "R2", "R3"]  # the station's robots, as in transport
    assert tether_v0.parallel_env().possible_agents == ["robot_0", "robot_1", "robot_2"]  # v0, kept for a release
    assert transport_v0.env().unwrapped.scenario.name == "corridor"
    with pytest.raises(EnvConfigError, match="scenario= is required"):
        transport_v0.TransportParallelEnv()  # the class itself names its scenario
