"""The task-family env ids: a task of the family per episode behind the family's padded, task-carrying layout."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils import seeding
from gymnasium.utils.env_checker import check_env

import impact_env  # noqa: F401  (registers the ids)
from impact_env.errors import EnvConfigError, ImpactEnvError
from impact_env.transport import family_env
from impact_env.transport.family_env import FAMILY_IDS, TaskFamilyEnv
from impact_env.transport.generate import FAMILIES, FAMILY_LIMITS, generate_task
from impact_env.transport.gym_env import TransportEnv
from impact_env.transport.task_observation import TaskObservation

NOISE = {"thrust_noise": 0.05, "initial_position_noise_m": 0.05}


@pytest.mark.parametrize("env_id", sorted(FAMILY_IDS))
def test_every_family_id_passes_gymnasiums_and_sb3s_checkers(env_id):
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = gym.make(env_id, **NOISE)
    check_env(env.unwrapped, skip_render_check=True)
    sb3_check_env(env.unwrapped, warn=False)
    obs, info = env.reset(seed=3)
    assert env.observation_space.contains(obs) and info["task"].startswith(FAMILY_IDS[env_id])


def test_one_id_per_family():
    assert sorted(FAMILY_IDS.values()) == sorted(FAMILIES)


def test_the_padded_spaces_are_the_familys_for_every_task():
    env = TaskFamilyEnv("gaps", tasks=[1, 2, "corridor", "narrow_gap"])
    for seed in range(8):
        obs, info = env.reset(seed=seed)
        assert obs.shape == env.observation_space.shape
        assert env.task_observation is not None and env.task_observation.spaces()[0] == env.observation_space


def _episode(env, seed, task=None):
    options = None if task is None else {"task": task}
    obs, info = env.reset(seed=seed, options=options)
    rng = np.random.default_rng(seed)
    out = [obs]
    terminated = False
    while not terminated:
        obs, reward, terminated, truncated, info = env.step(rng.uniform(-1, 1, env.action_space.shape))
        out += [obs, np.array([reward, info["robustness"]])]
    return info["task"], np.concatenate(out)


def test_same_seed_same_task_and_trajectory_over_a_whole_episode():
    env = TaskFamilyEnv("throw_and_catch", **NOISE)
    first, second, other = _episode(env, 5), _episode(env, 5), _episode(env, 6)
    assert first[0] == second[0] and np.array_equal(first[1], second[1])
    assert other[0] != first[0]


def test_an_episode_is_the_transport_env_on_its_task_seen_through_the_padded_layout():
    env = TaskFamilyEnv("obstacle_avoidance", **NOISE)
    obs, info = env.reset(seed=11, options={"task": 4})
    scenario = generate_task("obstacle_avoidance", 4)
    assert info["task"] == scenario.name
    inner_seed = int(seeding.np_random(11)[0].integers(2**63))  # the family env's first draw after seeding
    plain = TransportEnv(scenario, **NOISE)
    layout = TaskObservation(scenario, FAMILY_LIMITS["obstacle_avoidance"])
    plain_obs, _ = plain.reset(seed=inner_seed)
    assert np.array_equal(obs, layout(plain_obs))
    rng = np.random.default_rng(0)
    for _ in range(50):
        action = rng.uniform(-1, 1, 3 * len(scenario.robots)).astype(np.float32)  # the padded layout is float32
        got = env.step(layout.pad_action(action))
        want = plain.step(action)
        assert np.array_equal(got[0], layout(want[0])) and got[1] == want[1]


def test_a_list_of_tasks_is_drawn_from_and_options_choose_one():
    env = TaskFamilyEnv("gaps", tasks=[3, "corridor"])
    seen = {env.reset(seed=s)[1]["task"] for s in range(20)}
    assert seen == {"gaps_3", "corridor"}
    assert env.reset(seed=0, options={"task": "narrow_gap"})[1]["task"] == "narrow_gap"


def test_the_cache_keeps_the_recent_tasks_and_closes_the_others(monkeypatch):
    monkeypatch.setattr(family_env, "CACHED_TASKS", 2)
    env = TaskFamilyEnv("throw_and_catch")
    for task in (1, 2, 3, 2):
        env.reset(seed=0, options={"task": task})
    assert list(env._envs) == [3, 2]


@pytest.mark.parametrize("kwargs, words", [
    ({"family": "gap"}, "did you mean 'gaps'"),
    ({"family": "gaps", "tasks": []}, "non-empty list"),
    ({"family": "gaps", "tasks": "corridor"}, "non-empty list"),
    ({"family": "gaps", "scenario": "corridor"}, "not scenario="),
    ({"family": "throw_and_catch", "tasks": ["obstacle_avoidance"]}, "obstacles"),
    ({"family": "gaps", "tasks": ["no_such_scenario"]}, "no_such_scenario"),
    ({"family": "gaps", "tasks": [1.5]}, "generated-task seed"),
])
def test_bad_arguments_are_typed_errors_that_say_what_to_give(kwargs, words):
    with pytest.raises(ImpactEnvError, match=words):  # EnvConfigError; the loader's ScenarioError for a name
        TaskFamilyEnv(**kwargs)


def test_step_before_reset_is_a_typed_error():
    with pytest.raises(EnvConfigError, match="reset"):
        TaskFamilyEnv("gaps").step(np.zeros(12))
