"""The goal-conditioned padded observation (impact_env/transport/task_observation.py)."""

from __future__ import annotations

import numpy as np
import pytest

from impact_env import load_scenario
from impact_env.errors import EnvConfigError
from impact_env.transport.generate import FAMILIES, FAMILY_LIMITS, FamilyLimits, generate_task
from impact_env.transport.gym_env import TransportEnv
from impact_env.transport.task_observation import TaskConditioned, TaskObservation, task_clauses


@pytest.mark.parametrize("family", FAMILIES)
def test_every_task_of_a_family_has_the_same_layout(family):
    sizes = {TaskObservation(generate_task(family, seed), FAMILY_LIMITS[family]).size for seed in range(6)}
    assert len(sizes) == 1


def test_the_layout_carries_bodies_time_regions_and_obstacles():
    sc = generate_task("obstacle_avoidance", 3)
    limits = FAMILY_LIMITS["obstacle_avoidance"]
    pad = TaskObservation(sc, limits)
    env = TransportEnv(sc)
    obs, _ = env.reset(seed=0)
    out = pad(obs)
    body = TaskObservation.BODY
    rows = obs[:-1].reshape(-1, 7)
    for i in range(len(sc.robots)):  # robots in the first slots
        assert out[body * i] == 1.0 and np.array_equal(out[body * i + 1: body * (i + 1)], rows[i])
    for i in range(len(sc.robots), limits.robots):  # absent robots: zeros
        assert not out[body * i: body * (i + 1)].any()
    first_object = body * limits.robots
    assert np.array_equal(out[first_object + 1: first_object + body], rows[len(sc.robots)])
    assert out[pad.bodies_size] == obs[-1]
    # the first clause: O1's goal, its centre relative to O1
    op, a, b, obj, region = task_clauses(sc)[0]
    j = pad.bodies_size + 1
    xmin, xmax, ymin, ymax = sc.region_map()[region].bounds
    assert np.allclose(out[j:j + 5], [1, xmin, xmax, ymin, ymax])
    assert np.allclose(out[j + 5:j + 7], [(xmin + xmax) / 2 - rows[len(sc.robots), 0],
                                          (ymin + ymax) / 2 - rows[len(sc.robots), 1]], atol=1e-5)
    assert np.allclose(out[j + 7:j + 10], [a / sc.tf_s, b / sc.tf_s, 0.0])  # G: always
    # the first obstacle's vertices, padded by repeating the last
    k = pad.bodies_size + 1 + pad.region_size * limits.regions
    v = sc.obstacles[0].polygon.vertices
    assert out[k] == 1.0
    got = out[k + 1:k + pad.obstacle_size].reshape(-1, 2)
    assert np.allclose(got[:len(v)], v) and np.allclose(got[len(v):], v[-1])
    env.close()


def test_actions_pad_and_unpad_and_the_wrapper_steps():
    sc = generate_task("gaps", 1)
    env = TaskConditioned(TransportEnv(sc), FAMILY_LIMITS["gaps"])
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs) and env.action_space.shape == (12,)
    action = env.action_space.sample()
    obs2, *_ = env.step(action)
    assert obs2.shape == obs.shape
    pad = env.task_observation
    small = action[:3 * len(sc.robots)]
    assert np.array_equal(pad.unpad_action(pad.pad_action(small)), small)
    with pytest.raises(EnvConfigError, match="a padded action has 12 numbers"):
        pad.unpad_action(small[:2])
    env.close()


def test_shipped_scenarios_of_the_families_fit_their_limits():
    for name, family in (("throw_and_catch_exp", "throw_and_catch"), ("narrow_gap", "gaps"),
                         ("timed_visits", "timed_visits"), ("obstacle_avoidance", "obstacle_avoidance")):
        pad = TaskObservation(load_scenario(name), FAMILY_LIMITS[family])
        assert pad.size == TaskObservation(generate_task(family, 0), FAMILY_LIMITS[family]).size


def test_a_scenario_beyond_the_limits_is_a_typed_error():
    with pytest.raises(EnvConfigError, match="4 robots; this observation pads to at most 2"):
        TaskObservation(load_scenario("four_robots"), FamilyLimits(2, 2, 2, 0, 0))
    with pytest.raises(EnvConfigError, match="4 timed region clauses"):
        TaskObservation(load_scenario("timed_visits"), FamilyLimits(4, 2, 2, 0, 0))
