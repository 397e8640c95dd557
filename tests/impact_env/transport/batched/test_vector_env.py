"""TransportVectorEnv: gymnasium.make_vec's vector entry point, next-step autoreset, partial resets, rendering.

Gymnasium 1.2 ships no checker for vector envs (``gymnasium.utils.env_checker`` takes one env), so the
checks here are its vector API's contract, stated in ``gymnasium.vector.VectorEnv`` and the autoreset
page, tested against the batched world driven by hand, and Gymnasium's own vector wrappers
(RecordEpisodeStatistics, RecordVideo) run on it.
"""

from __future__ import annotations

import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.wrappers.vector import RecordEpisodeStatistics, RecordVideo

import impact_env
from impact_env.errors import EnvConfigError

SCENARIOS = Path(impact_env.__file__).parent / "transport" / "scenarios"
ID = "impact_env/ThrowAndCatchExp-v0"  # the shortest shipped horizon (200 steps)


def actions_for(envs, seed: int, steps: int) -> np.ndarray:
    return np.random.default_rng(seed).uniform(-1, 1, (steps, envs.num_envs, envs.single_action_space.shape[0]))


@pytest.mark.parametrize("env_id", [*impact_env.GYM_IDS, "impact_env/Transport-v0"])
def test_make_vec_returns_the_batched_world_for_every_transport_id(env_id):
    from impact_env.transport.batched.vector_env import TransportVectorEnv

    kwargs = {"scenario": str(SCENARIOS / "two_objects.toml")} if env_id.endswith("Transport-v0") else {}
    envs = gym.make_vec(env_id, num_envs=3, vectorization_mode="vector_entry_point", **kwargs)
    single = gym.make(env_id, **kwargs)
    assert isinstance(envs, TransportVectorEnv) and isinstance(envs, VectorEnv) and envs.num_envs == 3
    assert envs.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    assert envs.single_observation_space == single.observation_space
    assert envs.single_action_space == single.action_space
    assert envs.observation_space.shape == (3, *single.observation_space.shape)
    assert envs.max_episode_steps == (single.spec.max_episode_steps)
    assert envs.spec.id == env_id and envs.spec.kwargs["num_envs"] == 3
    obs, infos = envs.reset(seed=0)
    assert obs in envs.observation_space
    obs, rewards, terms, truncs, infos = envs.step(envs.action_space.sample())
    assert obs in envs.observation_space and obs.dtype == np.float32
    assert rewards.shape == (3,) and rewards.dtype == np.float64
    assert terms.dtype == bool and truncs.dtype == bool and not (terms.any() or truncs.any())
    for key in ("robustness", "is_success", "fuel_Ns", "time_s", "impacts"):
        assert infos[key].shape == (3,) and infos[f"_{key}"].all()
    np.testing.assert_allclose(infos["time_s"], 0.1, rtol=1e-6)
    single.close()
    envs.close()


def test_make_vec_picks_the_batched_world_and_sync_still_makes_pymunk_envs():
    from impact_env.transport.batched.vector_env import TransportVectorEnv

    assert isinstance(gym.make_vec(ID, num_envs=2), TransportVectorEnv)  # Gymnasium prefers the vector entry point
    sync = gym.make_vec(ID, num_envs=2, vectorization_mode="sync")
    assert isinstance(sync, gym.vector.SyncVectorEnv) and not isinstance(sync, TransportVectorEnv)
    sync.close()


def test_without_torch_the_vector_entry_point_names_both_ways_out(monkeypatch):
    from impact_env.transport.vector_entry import make_vector_env

    monkeypatch.setitem(sys.modules, "torch", None)  # find_spec reports it missing
    with pytest.raises(EnvConfigError, match=r"impact_env\[rl\].*vectorization_mode='sync'"):
        make_vector_env("corridor", 2)


def test_transport_v0_needs_a_scenario():
    with pytest.raises(EnvConfigError, match="scenario"):
        gym.make_vec("impact_env/Transport-v0", num_envs=2, vectorization_mode="vector_entry_point")


def test_env_options_pass_through_and_are_checked():
    from impact_env.transport.batched.vector_env import TransportVectorEnv

    envs = gym.make_vec(ID, num_envs=2, vectorization_mode="vector_entry_point", reward_mode="sparse",
                        thrust_noise=0.05)
    assert envs.world.reward_mode == "sparse" and envs.world.thrust_noise == 0.05
    with pytest.raises(EnvConfigError, match="reward_mode"):
        gym.make_vec(ID, num_envs=2, vectorization_mode="vector_entry_point", reward_mode="dens")
    with pytest.raises(EnvConfigError, match="max_episode_steps"):
        TransportVectorEnv("corridor", 2, max_episode_steps=0)
    with pytest.raises(EnvConfigError, match="render_mode"):
        TransportVectorEnv("corridor", 2, render_mode="human")
    envs = TransportVectorEnv("corridor", 2)
    envs.reset(seed=0)
    with pytest.raises(EnvConfigError, match="reset_mask"):
        envs.reset(options={"mask": [True, False]})


def run(envs, seed: int, actions: np.ndarray):
    out = [envs.reset(seed=seed)]
    out += [envs.step(a) for a in actions]
    return out


def test_same_seed_same_trajectory_through_an_autoreset():
    from impact_env.transport.batched.vector_env import TransportVectorEnv

    envs = TransportVectorEnv("throw_and_catch_exp", 2, max_episode_steps=6, thrust_noise=0.05,
                              initial_position_noise_m=0.05)
    actions = actions_for(envs, 0, 15)
    first, second = run(envs, 4, actions), run(envs, 4, actions)
    for a, b in zip(first, second):
        for x, y in zip(a, b):
            if isinstance(x, dict):
                assert x.keys() == y.keys() and all(np.array_equal(x[k], y[k]) for k in x)
            else:
                assert np.array_equal(x, y)
    other = run(envs, 5, actions)
    assert not np.array_equal(first[0][0], other[0][0])  # the start noise differs with the seed


def test_next_step_autoreset_matches_the_world_reset_by_hand():
    """Truncation at max_episode_steps; the next step returns the next episode's first observation with reward 0
    and no termination, ignores its action, and every later step is the world's, as if reset by hand."""
    import torch

    from impact_env.transport.batched import BatchedTransportWorld
    from impact_env.transport.batched.vector_env import TransportVectorEnv

    steps, N = 5, 2
    kwargs = {"thrust_noise": 0.05, "initial_position_noise_m": 0.05}
    envs = TransportVectorEnv("throw_and_catch_exp", N, max_episode_steps=steps, **kwargs)
    world = BatchedTransportWorld("throw_and_catch_exp", N, **kwargs)
    actions = actions_for(envs, 1, 2 * steps + 3).astype(np.float32)
    obs, _ = envs.reset(seed=7)
    assert np.array_equal(obs, world.reset(seeds=7).numpy())
    for t, a in enumerate(actions):
        obs, rewards, terms, truncs, infos = envs.step(a)
        if t in (steps, 2 * steps + 1):  # the autoreset steps
            expected = world.reset(mask=torch.ones(N, dtype=torch.bool)).numpy()
            assert np.array_equal(obs, expected) and not rewards.any() and not (terms.any() or truncs.any())
            assert not infos["impacts"].any() and not infos["time_s"].any()
            continue
        w_obs, w_reward, w_term, _, w_info = world.step(a)
        assert np.array_equal(obs, w_obs.numpy()) and np.array_equal(rewards, w_reward.double().numpy())
        assert np.array_equal(terms, w_term.numpy())
        assert truncs.all() == (t in (steps - 1, 2 * steps)) and truncs.all() == truncs.any()
        assert np.array_equal(infos["robustness"], w_info["robustness"].numpy())


def test_autoreset_step_ignores_the_action():
    from impact_env.transport.batched.vector_env import TransportVectorEnv

    envs = TransportVectorEnv("throw_and_catch_exp", 2, max_episode_steps=2, thrust_noise=0.05)
    actions = actions_for(envs, 2, 3)
    out = []
    for last in (actions[2], -actions[2]):
        envs.reset(seed=3)
        envs.step(actions[0])
        envs.step(actions[1])
        out.append(envs.step(last))
    assert np.array_equal(out[0][0], out[1][0]) and np.array_equal(out[0][1], out[1][1])


def test_the_horizon_terminates_and_the_time_limit_truncates_together():
    envs = gym.make_vec(ID, num_envs=2, vectorization_mode="vector_entry_point")
    envs.reset(seed=0)
    zeros = np.zeros(envs.action_space.shape, dtype=np.float32)
    for _ in range(envs.max_episode_steps - 1):
        _, _, terms, truncs, _ = envs.step(zeros)
        assert not (terms.any() or truncs.any())
    obs, _, terms, truncs, _ = envs.step(zeros)
    assert terms.all() and truncs.all() and (obs[:, -1] == 0).all()  # time left: none
    obs, rewards, terms, truncs, _ = envs.step(zeros)
    assert not (terms.any() or truncs.any() or rewards.any()) and (obs[:, -1] == 1).all()


def test_partial_reset_leaves_the_other_envs_on_their_trajectory():
    from impact_env.transport.batched.vector_env import TransportVectorEnv

    kwargs = {"thrust_noise": 0.05, "initial_position_noise_m": 0.05}
    envs = TransportVectorEnv("two_objects", 3, **kwargs)
    ref = TransportVectorEnv("two_objects", 3, **kwargs)
    actions = actions_for(envs, 3, 8)
    envs.reset(seed=11)
    ref.reset(seed=11)
    for t, a in enumerate(actions):
        if t == 3:
            obs, infos = envs.reset(options={"reset_mask": np.array([False, True, False])})
            assert infos["_robustness"].tolist() == [False, True, False] and obs[1, -1] == 1.0
        obs, rewards, _, _, _ = envs.step(a)
        r_obs, r_rewards, _, _, _ = ref.step(a)
        assert np.array_equal(obs[[0, 2]], r_obs[[0, 2]]) and np.array_equal(rewards[[0, 2]], r_rewards[[0, 2]])
        if t >= 3:
            assert not np.array_equal(obs[1], r_obs[1])


def test_an_autoreset_of_some_envs_leaves_the_others_on_their_trajectory():
    from impact_env.transport.batched.vector_env import TransportVectorEnv

    kwargs = {"thrust_noise": 0.05, "impact_velocity_noise_mps": 0.05}
    envs = TransportVectorEnv("throw_and_catch_exp", 2, max_episode_steps=5, **kwargs)
    ref = TransportVectorEnv("throw_and_catch_exp", 2, **kwargs)
    actions = actions_for(envs, 6, 7)
    envs.reset(seed=2)
    ref.reset(seed=2)
    for t, a in enumerate(actions):
        if t == 2:  # env 1 starts again: from now on its episode runs 3 steps behind env 0's
            envs.reset(options={"reset_mask": np.array([False, True])})
            ref.reset(options={"reset_mask": np.array([False, True])})
        obs, rewards, terms, truncs, _ = envs.step(a)
        r_obs, r_rewards, _, _, _ = ref.step(a)
        assert truncs.tolist() == [t == 4, t == 6]
        assert np.array_equal(obs[1], r_obs[1]) and rewards[1] == r_rewards[1]
        if t == 5:  # env 0's autoreset step, env 1's fourth step
            assert obs[0, -1] == 1.0 and rewards[0] == 0.0


def test_record_episode_statistics_counts_whole_episodes():
    from impact_env.transport.batched.vector_env import TransportVectorEnv

    envs = RecordEpisodeStatistics(TransportVectorEnv("throw_and_catch_exp", 3, max_episode_steps=4))
    envs.reset(seed=0)
    total = np.zeros(3)
    for a in actions_for(envs, 4, 4):
        _, rewards, _, truncs, infos = envs.step(a)
        total += rewards
    assert truncs.all() and "episode" in infos
    np.testing.assert_allclose(infos["episode"]["r"], total, rtol=1e-6)
    assert (infos["episode"]["l"] == 4).all()


def test_render_draws_the_envs_it_is_asked_for(tmp_path):
    from impact_env.transport.batched.vector_env import TransportVectorEnv

    envs = TransportVectorEnv("two_objects", 4, render_mode="rgb_array", render_width_px=120)
    assert envs.render() is not None  # before reset: the start state
    envs.reset(seed=0)
    frames = envs.render()
    assert len(frames) == 4
    first = frames[0]
    assert first.dtype == np.uint8 and first.ndim == 3 and first.shape[1] == 120 and first.shape[2] == 3
    assert np.array_equal(frames[-1], envs.world.render_rgb(3, 120))
    assert TransportVectorEnv("two_objects", 1).render() is None
    envs.step(envs.action_space.sample())
    with pytest.raises(EnvConfigError, match="render"):
        frames[1]
    with pytest.raises(IndexError):
        envs.render()[4]


def test_record_video_writes_a_video_of_the_first_env(tmp_path):
    from impact_env.transport.batched.vector_env import TransportVectorEnv

    envs = RecordVideo(TransportVectorEnv("throw_and_catch_exp", 64, render_mode="rgb_array", render_width_px=96,
                                          max_episode_steps=5), str(tmp_path), record_first_only=True,
                       episode_trigger=lambda episode: episode == 0)
    envs.reset(seed=0)
    for a in actions_for(envs, 5, 7):
        envs.step(a)
    envs.close()
    videos = list(tmp_path.glob("*.mp4"))
    assert len(videos) == 1 and videos[0].stat().st_size > 0
