"""The Gymnasium environment: API checkers, rewards, determinism, pickling, bad actions."""

from __future__ import annotations

import pickle

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import impact_env
from impact_env.errors import ActionError, ScenarioError
from impact_env.stl import robustness
from impact_env.transport.gym_env import TransportEnv

IDS = ["impact_env/Corridor-v0", "impact_env/ObstacleAvoidance-v0", "impact_env/ThrowAndCatchExp-v0"]


@pytest.mark.parametrize("env_id", IDS)
def test_gymnasium_check_env(env_id):
    env = gym.make(env_id)
    check_env(env.unwrapped)
    env.close()


def test_stable_baselines3_check_env():
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    sb3_check_env(TransportEnv("corridor"), warn=True)


def test_transport_v0_takes_a_scenario_name_or_path(tmp_path):
    env = gym.make("impact_env/Transport-v0", scenario="throw_and_catch_exp")
    assert env.unwrapped.scenario.name == "throw_and_catch_exp"
    with pytest.raises(ScenarioError, match="unknown scenario"):
        gym.make("impact_env/Transport-v0", scenario="nowhere")


def test_spaces_and_observation_layout():
    env = TransportEnv("corridor")
    obs, info = env.reset(seed=0)
    assert env.action_space.shape == (6,) and env.observation_space.shape == (3 * 7 + 1,)
    assert obs.dtype == np.float32
    np.testing.assert_allclose(obs[0:2], [1.0, 1.0])  # R1 position
    np.testing.assert_allclose(obs[7:9], [1.0, 9.0])  # R2
    np.testing.assert_allclose(obs[14:16], [1.0, 2.0])  # O1
    np.testing.assert_allclose(obs[4:6], [1.0, 0.0])  # cos, sin of heading 0
    assert obs[-1] == 1.0
    assert set(info) >= {"robustness", "is_success", "impacts", "fuel_Ns"}


def _rollout(env, seed, steps, actions_seed=123):
    rng = np.random.default_rng(actions_seed)
    obs, _ = env.reset(seed=seed)
    out = [obs]
    for _ in range(steps):
        obs, *_ = env.step(rng.uniform(-1, 1, env.action_space.shape))
        out.append(obs)
    return np.array(out)


def test_determinism_over_300_steps():
    kwargs = {"thrust_noise": 0.05, "initial_position_noise_m": 0.05}
    a = _rollout(TransportEnv("corridor", **kwargs), seed=7, steps=300)
    b = _rollout(TransportEnv("corridor", **kwargs), seed=7, steps=300)
    c = _rollout(TransportEnv("corridor", **kwargs), seed=8, steps=300)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)


def test_dense_rewards_sum_to_final_robustness_and_match_offline():
    """Run a full corridor episode: the dense rewards sum to the trace's offline robustness."""
    env = TransportEnv("corridor")
    core = env.core
    obs, _ = env.reset(seed=0)
    rng = np.random.default_rng(0)
    total, done, positions = 0.0, False, [[s[:2] for s in core._state]]
    steps = 0
    while not done:
        # push the object with R1 for a while so the trace has impacts and a changing robustness
        action = np.array([0.0, 1.0, 0.0, 0.0, 0.0, 0.0]) if steps < 40 else rng.uniform(-0.1, 0.1, 6)
        obs, reward, terminated, truncated, info = env.step(action)
        total += reward
        positions.append([s[:2] for s in core._state])
        done = terminated or truncated
        steps += 1
    assert steps == 1000  # horizon 100 s at 0.1 s
    trace = {name: np.array(positions)[:, i] for i, name in enumerate(core.body_names)}
    offline = robustness(env.scenario.formula, trace, env.scenario.region_map(), 0.1)
    assert info["robustness"] == pytest.approx(offline, abs=1e-9)
    assert total == pytest.approx(offline, abs=1e-9)
    assert info["is_success"] == (offline > 0)


def test_conjuncts_reward_credits_a_wall_graze_at_once():
    """R1 thrusts into wall W1 while the object sits still. Under "dense" the task's robustness is pinned at
    -5.25 by "F in(O1, goal)", so the graze earns nothing; under "conjuncts" it costs at once, and the
    rewards sum to the mean final robustness of the conjuncts. The reported robustness is the task's."""
    from impact_env.stl import conjuncts

    action = np.zeros(6, dtype=np.float32)
    action[0] = -1.0  # R1 full thrust in -x (body frame = world frame at heading 0)
    totals, infos = {}, {}
    for mode in ("dense", "conjuncts"):
        env = TransportEnv("corridor", reward_mode=mode)
        env.reset(seed=0)
        rewards = [env.step(action)[1] for _ in range(300)]  # bounces die out by ~25 s (e = 0.75)
        totals[mode], infos[mode] = sum(rewards[1:]), env.core.log.robustness
        if mode == "conjuncts":
            positions = env.core._positions()
            parts = [m.value for m in env.core.conjunct_monitors]
            assert len(parts) == len(conjuncts(env.scenario.formula)) == 7
            assert sum(rewards) == pytest.approx(np.mean(parts), abs=1e-9)
            assert positions["R1"][0] == pytest.approx(0.2, abs=0.02)  # resting against the wall
    assert totals["dense"] == 0.0 and infos["dense"] == infos["conjuncts"] == pytest.approx(-5.25)
    assert totals["conjuncts"] == pytest.approx(-0.8 / 7, abs=0.01)  # R1's clearance 1.0 -> 0.2, one of seven


def test_sparse_reward_and_fuel_penalty():
    env = TransportEnv("throw_and_catch_exp", reward_mode="sparse", fuel_penalty=0.5)
    env.reset(seed=0)
    rewards, infos = [], []
    done = False
    while not done:
        _, r, term, trunc, info = env.step(np.full(6, 0.5))
        rewards.append(r)
        infos.append(info)
        done = term or trunc
    fuel_step = np.hypot(1.4, 1.4) * 2 * 0.1  # two robots at half thrust on both axes
    assert rewards[0] == pytest.approx(-0.5 * fuel_step)
    assert rewards[-1] == pytest.approx(infos[-1]["robustness"] - 0.5 * fuel_step)
    assert infos[-1]["fuel_Ns"] == pytest.approx(fuel_step * len(rewards))


def test_zero_controller_fails_and_objects_never_move():
    env = TransportEnv("throw_and_catch_exp")
    obs0, _ = env.reset(seed=0)
    done = False
    while not done:
        obs, _, term, trunc, info = env.step(np.zeros(6))
        done = term or trunc
    np.testing.assert_array_equal(obs[:-1], obs0[:-1])
    # the object sits at (1.5, 0): 0.6 m left of the goal box, so the robustness is -0.6
    assert info["robustness"] == pytest.approx(-0.6, abs=1e-6)
    assert info["is_success"] is False and info["impacts"] == []


def test_impacts_are_reported_in_info():
    env = TransportEnv("corridor")
    env.reset(seed=0)
    seen = []
    for _ in range(60):  # R1 thrusts up into the object 0.6 m above it
        *_, info = env.step([0.0, 1.0, 0.0, 0.0, 0.0, 0.0])
        seen += info["impacts"]
    first = seen[0]
    assert {first["a"], first["b"]} == {"R1", "O1"}
    assert first["impulse"] > 0 and 0 < first["time"] < 6.0


def test_nan_and_out_of_range_actions():
    env = TransportEnv("corridor")
    env.reset(seed=0)
    with pytest.raises(ActionError, match="NaN"):
        env.step(np.array([np.nan, 0, 0, 0, 0, 0]))
    with pytest.raises(ActionError, match="6 numbers"):
        env.step(np.zeros(5))
    env.step(np.full(6, 50.0))  # clipped to the limits
    assert env.core.last_wrenches[0] == pytest.approx((2.8, 2.8, 0.2))


def test_step_after_end_and_before_reset():
    env = TransportEnv("throw_and_catch_exp")
    with pytest.raises(impact_env.ImpactEnvError, match="reset"):
        env.step(np.zeros(6))
    env.reset(seed=0)
    for _ in range(env.core.horizon_steps):
        env.step(np.zeros(6))
    with pytest.raises(impact_env.ImpactEnvError, match="episode has ended"):
        env.step(np.zeros(6))


def test_pickle_round_trip():
    env = TransportEnv("obstacle_avoidance", reward_mode="sparse", fuel_penalty=0.1)
    clone = pickle.loads(pickle.dumps(env))
    assert clone.scenario.name == "obstacle_avoidance" and clone.core.reward_mode == "sparse"
    a = _rollout(env, seed=3, steps=20)
    b = _rollout(clone, seed=3, steps=20)
    assert np.array_equal(a, b)


def test_rgb_array_render_and_record_video(tmp_path):
    env = gym.make("impact_env/ThrowAndCatchExp-v0", render_mode="rgb_array")
    env = gym.wrappers.RecordVideo(env, str(tmp_path), episode_trigger=lambda k: True, disable_logger=True)
    env.reset(seed=0)
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
    for _ in range(30):
        env.step(env.action_space.sample())
    env.close()
    assert list(tmp_path.glob("*.mp4"))


def test_invalid_options_raise():
    with pytest.raises(ValueError, match="reward_mode"):
        TransportEnv("corridor", reward_mode="shaped")
    with pytest.raises(ValueError, match="fuel_penalty"):
        TransportEnv("corridor", fuel_penalty=-1)
    with pytest.raises(ValueError, match="restitution"):
        TransportEnv("corridor", restitution=2.0)
    with pytest.raises(ValueError, match="render_mode"):
        TransportEnv("corridor", render_mode="ansi")
