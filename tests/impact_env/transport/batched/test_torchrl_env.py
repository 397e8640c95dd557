"""TransportTorchRLEnv: TorchRL's check_env_specs, the ``agents`` group, partial resets, seeds and a collector."""

from __future__ import annotations

from typing import TYPE_CHECKING

import pytest

from tests.optional import requires

if TYPE_CHECKING:
    import torch

    from impact_env.transport.batched.torchrl_env import TransportTorchRLEnv

# torchrl looked up, not imported, while the suite is collected: the tests import it
pytestmark = requires("torchrl")

SCENARIO = "throw_and_catch_exp"  # 200 steps per episode


def random_actions(env: TransportTorchRLEnv, seed: int) -> torch.Tensor:
    import torch

    g = torch.Generator().manual_seed(seed)
    return torch.rand(env.world.num_envs, env.world.n_robots, 3, generator=g) * 2 - 1


@pytest.mark.parametrize("scenario", [SCENARIO, "four_robots"])
def test_check_env_specs(scenario):
    from torchrl.envs.utils import check_env_specs

    from impact_env.transport.batched.torchrl_env import GROUP, TransportTorchRLEnv

    env = TransportTorchRLEnv(scenario, 3)
    check_env_specs(env, seed=0)
    R = env.world.n_robots
    assert env.group_map == {GROUP: [r.name for r in env.scenario.robots]} and len(env.group_map[GROUP]) == R
    assert env.full_action_spec[GROUP, "action"].shape == (3, R, 3)
    assert env.full_observation_spec[GROUP, "observation"].shape == (3, R, env.world.obs_size)
    assert env.full_reward_spec[GROUP, "reward"].shape == (3, R, 1)


def test_step_is_the_worlds_step_seen_by_every_robot():
    import torch

    from impact_env.transport.batched import BatchedTransportWorld
    from impact_env.transport.batched.torchrl_env import GROUP, TransportTorchRLEnv

    env = TransportTorchRLEnv(SCENARIO, 2, thrust_noise=0.05)
    world = BatchedTransportWorld(SCENARIO, 2, thrust_noise=0.05)
    env.set_seed(5)
    td = env.reset()
    world.reset(seeds=5)
    assert torch.equal(td[GROUP, "observation"], world.agent_observations()) and torch.equal(td["state"],
                                                                                             world.state())
    action = random_actions(env, 0)
    td[GROUP, "action"] = action
    out = env.step(td)["next"]
    obs, reward, terminated, _, info = world.step(action)
    assert torch.equal(out["state"], obs) and torch.equal(out[GROUP, "observation"], world.agent_observations())
    assert torch.equal(out[GROUP, "reward"], reward.reshape(2, 1, 1).expand(2, 2, 1))
    assert torch.equal(out[GROUP, "info", "robustness"][:, 0, 0], info["robustness"])
    assert not out["done"].any() and not out[GROUP, "done"].any()


def test_rollout_through_the_horizon_resets_the_ended_envs():
    from impact_env.transport.batched.torchrl_env import GROUP, TransportTorchRLEnv

    env = TransportTorchRLEnv(SCENARIO, 2)
    env.set_seed(0)
    td = env.rollout(205, break_when_any_done=False)
    done = td["next", "done"][..., 0]
    assert done[:, 199].all() and done.sum() == 2 and td["next", "terminated"][:, 199].all()
    assert not td["next", "truncated"].any() and td["next", GROUP, "done"][:, 199].all()
    assert (td["next", "state"][:, 199, -1] == 0).all() and (td["state"][:, 200, -1] == 1).all()


def test_reset_mask_resets_only_the_envs_it_names():
    import torch
    from tensordict import TensorDict

    from impact_env.transport.batched.torchrl_env import GROUP, TransportTorchRLEnv

    env = TransportTorchRLEnv(SCENARIO, 3)
    env.set_seed(1)
    td = env.reset()
    for t in range(3):
        td[GROUP, "action"] = random_actions(env, t)
        td = env.step(td)["next"]
    before = env.world.state().clone()
    mask = torch.tensor([[False], [True], [False]])
    td["_reset"] = mask  # TorchRL's partial reset: the other rows of the output are the input's
    out = env.reset(td)
    assert torch.equal(env.world.state()[[0, 2]], before[[0, 2]]) and env.world.state()[1, -1] == 1.0
    assert torch.equal(out["state"], env.world.state()) and not out["done"].any()
    assert torch.equal(env._reset(TensorDict({"_reset": mask}, batch_size=(3,)))["state"], env.world.state())


def test_same_seed_same_rollout():
    import torch

    from impact_env.transport.batched.torchrl_env import TransportTorchRLEnv

    env = TransportTorchRLEnv(SCENARIO, 2, thrust_noise=0.05, initial_position_noise_m=0.05)
    rollouts = []
    for _ in range(2):
        env.set_seed(3)
        torch.manual_seed(0)  # the rollout's random actions
        rollouts.append(env.rollout(6))
    assert torch.equal(rollouts[0]["next", "state"], rollouts[1]["next", "state"])
    env.set_seed(4)
    assert not torch.equal(env.rollout(1)["state"], rollouts[0]["state"][:, :1])


def test_a_collector_gathers_frames_across_episode_ends():
    import torch
    from torchrl.collectors import SyncDataCollector

    from impact_env.transport.batched.torchrl_env import TransportTorchRLEnv

    env = TransportTorchRLEnv(SCENARIO, 4)
    collector = SyncDataCollector(env, policy=None, frames_per_batch=4 * 150, total_frames=4 * 300)
    batches = list(collector)
    collector.shutdown()
    assert len(batches) == 2 and batches[0].batch_size == (4, 150)
    done = torch.cat([b["next", "done"] for b in batches], dim=1)[..., 0]
    assert done[:, 199].all() and done.sum() == 4  # each env's episode ended once, at the horizon
