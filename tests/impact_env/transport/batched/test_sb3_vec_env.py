"""TransportSB3VecEnv: SB3's VecEnv conventions (same-step reset, terminal_observation) and a short PPO run on it."""

from __future__ import annotations

import numpy as np
import pytest

from impact_env.errors import EnvConfigError
from tests.optional import requires

# SB3 looked up, not imported, while the suite is collected (it brings tensorboard's stubs): the tests import it
pytestmark = requires("stable_baselines3")


def TransportSB3VecEnv(*args, **kwargs):  # noqa: N802 - stands for the class, imported when a test runs
    from impact_env.transport.batched.sb3_vec_env import TransportSB3VecEnv

    return TransportSB3VecEnv(*args, **kwargs)

SCENARIO = "throw_and_catch_exp"  # 200 steps per episode


def actions_for(venv, seed: int, steps: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.uniform(-1, 1, (steps, venv.num_envs, venv.action_space.shape[0])).astype(np.float32)


def test_spaces_and_one_step():
    from stable_baselines3.common.vec_env import VecMonitor

    venv = TransportSB3VecEnv(SCENARIO, 3)
    assert venv.num_envs == 3 and venv.render_mode == "rgb_array"
    assert venv.observation_space.shape == (22,) and venv.action_space.shape == (6,)
    venv.seed(0)
    obs = venv.reset()
    assert obs.shape == (3, 22) and obs.dtype == np.float32 and all(o in venv.observation_space for o in obs)
    obs, rewards, dones, infos = venv.step(actions_for(venv, 0, 1)[0])
    assert rewards.shape == (3,) and rewards.dtype == np.float32 and dones.dtype == bool and not dones.any()
    assert len(infos) == 3 and set(infos[0]) == {"robustness", "is_success", "fuel_Ns", "time_s", "impacts"}
    assert venv.get_attr("horizon_steps") == [200] * 3 and venv.env_is_wrapped(VecMonitor) == [False] * 3
    assert venv.has_attr("dt_s") and not venv.has_attr("no_such_attribute")


def test_seed_sets_the_next_reset_and_trajectories_repeat():
    import torch

    from impact_env.transport.batched import BatchedTransportWorld

    venv = TransportSB3VecEnv(SCENARIO, 2, thrust_noise=0.05, initial_position_noise_m=0.05)
    actions = actions_for(venv, 1, 5)
    runs = []
    for _ in range(2):
        venv.seed(9)
        runs.append([venv.reset()] + [venv.step(a)[0] for a in actions])
    assert all(np.array_equal(a, b) for a, b in zip(*runs))
    world = BatchedTransportWorld(SCENARIO, 2, thrust_noise=0.05, initial_position_noise_m=0.05)
    assert np.array_equal(runs[0][0], world.reset(seeds=9).numpy())
    for a, obs in zip(actions, runs[0][1:]):
        assert np.array_equal(obs, world.step(torch.as_tensor(a))[0].numpy())


def test_an_ended_episode_resets_in_the_same_step_with_its_terminal_observation():
    import torch

    from impact_env.transport.batched import BatchedTransportWorld

    venv = TransportSB3VecEnv(SCENARIO, 2, thrust_noise=0.05)
    world = BatchedTransportWorld(SCENARIO, 2, thrust_noise=0.05)
    venv.seed(3)
    venv.reset()
    world.reset(seeds=3)
    actions = actions_for(venv, 2, 202)
    for t, a in enumerate(actions):
        obs, rewards, dones, infos = venv.step(a)
        w_obs, w_reward, w_term, _, _ = world.step(torch.as_tensor(a))
        assert np.array_equal(rewards, w_reward.numpy())
        if t == 199:
            assert dones.all() and w_term.all()
            for i in range(2):
                assert np.array_equal(infos[i]["terminal_observation"], w_obs[i].numpy())
                assert infos[i]["TimeLimit.truncated"] is False  # the horizon is the task's: a termination
            w_obs = world.reset(mask=w_term)
            assert (obs[:, -1] == 1.0).all()  # the next episode's first observation
        else:
            assert not dones.any() and "terminal_observation" not in infos[0]
        assert np.array_equal(obs, w_obs.numpy())


def test_images_are_the_chosen_envs():
    venv = TransportSB3VecEnv(SCENARIO, 4, render_env_indices=(1, 3), render_width_px=100)
    venv.seed(0)
    venv.reset()
    images = venv.get_images()
    assert len(images) == 2 and images[0].shape[1] == 100 and images[0].dtype == np.uint8
    assert np.array_equal(images[1], venv.world.render_rgb(3, 100))
    assert venv.render().ndim == 3  # SB3 tiles them
    with pytest.raises(EnvConfigError, match="render_env_indices"):
        TransportSB3VecEnv(SCENARIO, 4, render_env_indices=(4,))
    with pytest.raises(EnvConfigError, match="share"):
        venv.set_attr("thrust_noise", 0.1)
    with pytest.raises(EnvConfigError, match="step_async"):
        venv.step_wait()


def test_ppo_learns_a_few_hundred_steps_through_vec_monitor_and_vec_normalize():
    """SB3's own use of a VecEnv: PPO's rollouts (with episode ends inside them), VecMonitor's episode records
    and VecNormalize's running statistics, for 4 x 256 env steps."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    venv = VecNormalize(VecMonitor(TransportSB3VecEnv(SCENARIO, 4, thrust_noise=0.05)))
    venv.seed(0)
    model = PPO("MlpPolicy", venv, n_steps=64, batch_size=128, n_epochs=2, seed=0, device="cpu",
                policy_kwargs={"net_arch": [32, 32]})
    before = [p.detach().clone() for p in model.policy.parameters()]
    model.learn(total_timesteps=1024)
    assert model.num_timesteps == 1024
    assert len(model.ep_info_buffer) == 4 and all(ep["l"] == 200 for ep in model.ep_info_buffer)
    assert any(not torch.equal(b, p) for b, p in zip(before, model.policy.parameters()))
    assert venv.obs_rms.count > 1000
    action, _ = model.predict(venv.reset(), deterministic=True)
    assert action.shape == (4, 6)
