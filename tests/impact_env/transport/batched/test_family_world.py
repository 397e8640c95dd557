"""TaskFamilyWorld: many tasks of a family in one batch, each env exactly its task's batched world, seen through
the family's padded layout; and stable-baselines3 training on it through TransportSB3VecEnv."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from impact_env.errors import EnvConfigError, ImpactEnvError
from impact_env.transport.generate import FAMILY_LIMITS, generate_task
from impact_env.transport.task_observation import TaskObservation
from tests.optional import requires

TASKS = [0, 1, "throw_and_catch_exp"]  # two generated tasks (other body counts, horizons) and the shipped one


def _family_world(**options):
    from impact_env.transport.batched.family_world import TaskFamilyWorld

    return TaskFamilyWorld("throw_and_catch", TASKS, 2, **options)


def test_each_env_is_its_tasks_world_in_the_padded_layout():
    """Same seeds and actions: every env's padded observation is TaskObservation of the lone world's
    observation of its task, step after step, and rewards and infos are that world's."""
    import torch

    from impact_env.transport.batched import BatchedTransportWorld

    family = _family_world(thrust_noise=0.05, initial_position_noise_m=0.05, dtype=torch.float64)
    alone = [BatchedTransportWorld(sc, 2, thrust_noise=0.05, initial_position_noise_m=0.05, dtype=torch.float64)
             for sc in family.scenarios]
    layouts = [TaskObservation(sc, FAMILY_LIMITS["throw_and_catch"]) for sc in family.scenarios]
    assert family.num_envs == 6 and family.obs_size == layouts[0].size
    assert family.action_size == 3 * FAMILY_LIMITS["throw_and_catch"].robots
    obs = family.reset(seeds=10)
    own = [w.reset(seeds=10 + 2 * k) for k, w in enumerate(alone)]
    rng = np.random.default_rng(0)
    for step in range(60):
        for k, layout in enumerate(layouts):
            for i in range(2):
                expected = layout(own[k][i].numpy())
                np.testing.assert_allclose(obs[2 * k + i].numpy(), expected, rtol=0, atol=1e-6,
                                           err_msg=f"task {k} env {i} step {step}")
        a = rng.uniform(-1, 1, (6, family.action_size))
        obs, reward, terminated, truncated, info = family.step(torch.as_tensor(a))
        parts = [w.step(torch.as_tensor(a[2 * k:2 * k + 2, :3 * w.n_robots])) for k, w in enumerate(alone)]
        own = [p[0] for p in parts]
        assert torch.equal(reward, torch.cat([p[1] for p in parts]))
        assert torch.equal(info["robustness"], torch.cat([p[4]["robustness"] for p in parts]))
        assert info["task_index"].tolist() == [0, 0, 1, 1, 2, 2]
        assert not terminated.any() and not truncated.any()


def test_the_padding_robots_numbers_are_ignored():
    import torch

    a = torch.as_tensor(np.random.default_rng(1).uniform(-1, 1, (6, 12)))
    runs = []
    for fill in (0.0, 1.0):
        world = _family_world(thrust_noise=0.05)
        world.reset(seeds=3)
        b = a.clone()
        for k, sc in enumerate(world.scenarios):
            b[2 * k:2 * k + 2, 3 * len(sc.robots):] = fill
        for _ in range(20):
            obs = world.step(b)[0]
        runs.append(obs)
    assert torch.equal(runs[0], runs[1])


def test_a_masked_reset_restarts_only_those_envs():
    import torch

    world = _family_world()
    first = world.reset(seeds=0)
    world.step(torch.zeros(6, world.action_size))
    moved = world.observation().clone()
    mask = torch.tensor([False, False, True, False, False, False])
    obs = world.reset(mask=mask)
    assert torch.equal(obs[2], first[2]) and torch.equal(obs[[0, 1, 3, 4, 5]], moved[[0, 1, 3, 4, 5]])


def test_bad_inputs_are_typed_errors():
    import torch

    from impact_env.transport.batched.family_world import TaskFamilyWorld

    with pytest.raises(EnvConfigError, match="tasks must be"):
        TaskFamilyWorld("throw_and_catch", [], 2)
    with pytest.raises(EnvConfigError, match="envs_per_task"):
        TaskFamilyWorld("throw_and_catch", [0], 0)
    with pytest.raises(EnvConfigError):
        TaskFamilyWorld("no_such_family", [0], 1)
    with pytest.raises(EnvConfigError, match="at most"):  # obstacles, which this family's layout has no slot for
        TaskFamilyWorld("throw_and_catch", ["obstacle_avoidance"], 1)
    slow = dataclasses.replace(generate_task("throw_and_catch", 1), control_period_s=0.2)
    with pytest.raises(EnvConfigError, match="control period"):
        TaskFamilyWorld("throw_and_catch", [0, slow], 1)
    world = TaskFamilyWorld("throw_and_catch", [0], 2)
    with pytest.raises(ImpactEnvError, match="reset"):
        world.step(torch.zeros(2, world.action_size))
    world.reset(seeds=0)
    with pytest.raises(EnvConfigError, match="padded action"):
        world.step(torch.zeros(2, 3))
    with pytest.raises(EnvConfigError, match="seeds"):
        world.reset(seeds=[1, 2, 3])


@requires("stable_baselines3")
def test_sb3_trains_one_policy_on_several_tasks():
    """TransportSB3VecEnv(world=...): SB3's VecEnv conventions over tasks of other horizons, and a short PPO run
    through VecMonitor and VecNormalize."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    from impact_env.transport.batched.sb3_vec_env import TransportSB3VecEnv

    with pytest.raises(EnvConfigError, match="not both"):
        TransportSB3VecEnv("corridor", 2, world=_family_world())
    raw = TransportSB3VecEnv(world=_family_world(thrust_noise=0.05))
    size = TaskObservation(raw.world.scenarios[0], FAMILY_LIMITS["throw_and_catch"]).size
    assert raw.num_envs == 6 and raw.observation_space.shape == (size,)
    raw.seed(0)
    raw.reset()
    _, _, dones, infos = raw.step(np.zeros((6, raw.action_space.shape[0]), dtype=np.float32))
    assert [info["task_index"] for info in infos] == [0, 0, 1, 1, 2, 2] and not dones.any()
    venv = VecNormalize(VecMonitor(raw))
    model = PPO("MlpPolicy", venv, n_steps=128, batch_size=256, n_epochs=1, seed=0, device="cpu",
                policy_kwargs={"net_arch": [32, 32]})
    before = [p.detach().clone() for p in model.policy.parameters()]
    horizons = sorted(w.horizon_steps for w in raw.world.worlds)
    model.learn(total_timesteps=6 * 128 * -(-horizons[0] // 128))
    assert any(not torch.equal(b, p) for b, p in zip(before, model.policy.parameters()))
    lengths = {ep["l"] for ep in model.ep_info_buffer}
    assert lengths and lengths <= set(horizons)  # the shortest task's episodes ended with their own horizon
