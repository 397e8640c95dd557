"""BenchMARL's task class for the batched impact world (the ``[marl]`` extra): specs, options, and MAPPO / IPPO
iterations through BenchMARL's own Experiment."""

from __future__ import annotations

import pytest

from impact_env.errors import EnvConfigError
from tests.optional import requires

# benchmarl imports torch, tensordict and torchrl (seconds): looked up here, imported by the tests
pytestmark = requires("benchmarl")


@pytest.fixture(autouse=True)
def _one_thread():
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def test_task_specs_split_the_envs_keys_as_benchmarl_expects():
    from baselines.batched.benchmarl_task import ImpactTask

    task = ImpactTask.THROW_AND_CATCH_EXP.get_task(config={"thrust_noise": 0.05})
    assert task.scenario == "throw_and_catch_exp" and task.env_name() == "impact_env"
    env = task.get_env_fun(num_envs=3, continuous_actions=True, seed=0, device="cpu")()
    assert env.batch_size == (3,) and env.world.thrust_noise == 0.05 and not env.world.compiled
    assert task.group_map(env) == {"agents": ["R1", "R2"]} and task.max_steps(env) == 200
    assert set(task.observation_spec(env).keys(True, True)) == {("agents", "observation")}
    assert set(task.info_spec(env).keys(True, True)) == {("agents", "info", "robustness"),
                                                          ("agents", "info", "is_success")}
    assert set(task.state_spec(env).keys()) == {"state"}
    assert task.action_spec(env)["agents", "action"].shape == (2, 3)
    assert task.supports_continuous_actions() and not task.supports_discrete_actions()
    assert task.action_mask_spec(env) is None


def test_task_options_are_checked():
    import torch

    from baselines.batched.benchmarl_task import ImpactTaskClass

    with pytest.raises(EnvConfigError, match="thrust_nosie"):
        ImpactTaskClass("corridor", {"thrust_nosie": 0.05})
    with pytest.raises(EnvConfigError, match="dtype"):
        ImpactTaskClass("corridor", {"dtype": "float16"})
    task = ImpactTaskClass("corridor", {"reward_mode": "sparse", "dtype": "float64"})
    env = task.get_env_fun(num_envs=2, continuous_actions=True, seed=None, device="cpu")()
    assert env.world.reward_mode == "sparse" and env.world.dtype == torch.float64


@pytest.mark.parametrize("algorithm", ["mappo", pytest.param("ippo", marks=pytest.mark.slow)])
def test_benchmarl_trains_a_few_iterations(algorithm, tmp_path):
    import torch
    from benchmarl.algorithms import IppoConfig, MappoConfig
    from benchmarl.experiment import Experiment, ExperimentConfig
    from benchmarl.models import MlpConfig

    from baselines.batched.benchmarl_task import ImpactTask

    ec = ExperimentConfig.get_from_yaml()
    ec.max_n_iters, ec.max_n_frames = 2, None
    ec.on_policy_collected_frames_per_batch = 8 * 50
    ec.on_policy_n_envs_per_worker = 8
    ec.on_policy_n_minibatch_iters = 1
    ec.on_policy_minibatch_size = 200
    ec.evaluation, ec.render, ec.loggers, ec.create_json = False, False, ["csv"], False
    ec.save_folder, ec.checkpoint_at_end = str(tmp_path), False
    ec.sampling_device = ec.train_device = ec.buffer_device = "cpu"
    mc = MlpConfig.get_from_yaml()
    mc.num_cells = [16, 16]
    algorithm_config = (MappoConfig if algorithm == "mappo" else IppoConfig).get_from_yaml()
    task = ImpactTask.THROW_AND_CATCH_EXP.get_task(config={"thrust_noise": 0.05})
    experiment = Experiment(task=task, algorithm_config=algorithm_config, model_config=mc, critic_model_config=mc,
                            seed=0, config=ec)
    before = [p.detach().clone() for p in experiment.policy.parameters()]
    experiment.run()
    assert experiment.n_iters_performed == 2 and experiment.total_frames == 800
    assert any(not torch.equal(b, p) for b, p in zip(before, experiment.policy.parameters()))
    if algorithm == "mappo":  # the final evaluation: deterministic and sampled, on both worlds, reproducible
        from baselines.batched.marl import MarlConfig, evaluate_impact

        cfg = MarlConfig("mappo", "throw_and_catch_exp", thrust_noise=0.05)
        first = evaluate_impact(experiment.policy, cfg, episodes=2, first_seed=7)
        again = evaluate_impact(experiment.policy, cfg, episodes=2, first_seed=7)
        assert first == again and first["episodes"] == 2 and first["first_seed"] == 7
        for scores in (first, first["sampled"]):
            for world in ("batched", "pymunk"):
                assert 0 <= scores[world]["success_rate"] <= 1 and torch.isfinite(
                    torch.tensor(scores[world]["robustness_mean"]))
        # sampled actions are drawn from the policy (reproducibly under a torch seed), the deterministic ones not
        from baselines.batched.marl import _policy_actions
        from impact_env.transport.batched import BatchedTransportWorld

        world = BatchedTransportWorld("throw_and_catch_exp", 3)
        world.reset(seeds=0)
        obs = world.agent_observations()
        mean = _policy_actions(experiment.policy, "agents", obs)
        assert torch.equal(mean, _policy_actions(experiment.policy, "agents", obs))
        torch.manual_seed(1)
        drawn = _policy_actions(experiment.policy, "agents", obs, sampled=True)
        torch.manual_seed(1)
        assert torch.equal(drawn, _policy_actions(experiment.policy, "agents", obs, sampled=True))
        assert not torch.allclose(drawn, mean)
