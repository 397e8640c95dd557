"""BC+RL (baselines/batched/bc_rl.py, bc_ppo.py) at tiny sizes on throw_and_catch_exp (200 steps an
episode): the start is the BC policy and its frozen observation statistics, the BC term holds the policy to
the expert and without it an update is SB3's PPO's, the critic warms up alone, the run folder resumes and
flies, the CLI, the config. A run here is 4 envs for a few dozen env-steps."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np
import pytest

from impact_env.cli import main
from impact_env.errors import ImpactEnvError
from tests.optional import requires
from tests.shipped_plans import path as committed_plan

pytestmark = requires("stable_baselines3")
SCENARIO = "throw_and_catch_exp"
NOISE = {"thrust_noise": 0.05, "initial_position_noise_m": 0.05}
TINY = {"num_envs": 4, "n_steps": 8, "batch_size": 16, "n_epochs": 1, "checkpoint_frames": 32, "eval_episodes": 2,
        "bc_batch_size": 64, "critic_warmup_rollouts": 0}


@pytest.fixture(scope="module")
def bc_folder(tmp_path_factory) -> Path:
    """A BC policy of 2 expert episodes (400 pairs): ``dagger --rounds 0``, whose rounds/ are the expert pairs."""
    from baselines.dagger import DAggerConfig, dagger

    out = tmp_path_factory.mktemp("bc") / "bc"
    return dagger(DAggerConfig(SCENARIO, rounds=0, initial_episodes=2, eval_episodes=0,
                               plan=str(committed_plan("sr", SCENARIO)), env_options=NOISE, epochs=20,
                               net_arch=(32, 32), out=str(out), quiet=True))


def tiny(bc_folder: Path, **kw):
    from baselines.batched.bc_rl import BcRlConfig

    return BcRlConfig(SCENARIO, str(bc_folder), **{**TINY, **kw})


def built(config):
    from baselines.batched.bc_rl import build
    from baselines.batched.sb3_ppo import make_venv

    return build(config, make_venv(config))


def test_the_fine_tuning_starts_from_the_bc_policy_with_its_frozen_statistics(bc_folder):
    """The same deterministic actions as the BC folder flown by `impact-env run`, on the expert's own states;
    the observation statistics are the BC fit's and stepping the world does not move them; the expert pairs
    are the DAgger run's labels."""
    from baselines.dagger import load_round
    from baselines.policy import SB3Controller
    from impact_env.transport.scenario import load_scenario

    model, venv = built(tiny(bc_folder))
    episodes = load_round(bc_folder, 0)
    assert len(model.expert_obs) == sum(e.steps for e in episodes) == 400
    bc = SB3Controller(load_scenario(SCENARIO), bc_folder / "model.zip")
    obs = episodes[0].observations[::20]
    mine = model.predict(venv.normalize_obs(obs), deterministic=True)[0]
    theirs = np.stack([bc.act(o, {}) for o in obs])
    np.testing.assert_allclose(mine, theirs, atol=1e-6)
    stored = json.loads((bc_folder / "vecnormalize.json").read_text())["obs_rms"]
    np.testing.assert_array_equal(venv.obs_rms.mean, stored["mean"])
    venv.reset()
    venv.step(np.zeros((4, venv.action_space.shape[0]), np.float32))
    np.testing.assert_array_equal(venv.obs_rms.mean, stored["mean"])
    np.testing.assert_array_equal(venv.obs_rms.var, stored["var"])


def test_a_large_bc_weight_pulls_the_policy_to_the_expert_and_weight_zero_lets_ppo_move_it_off(bc_folder):
    """The same tiny fine-tuning (a large learning rate, 4 epochs, 2 rollouts) with and without the BC term:
    with it, the action error against the expert's pairs falls (the BC fit held one of the two episodes out);
    without it, PPO alone moves the policy away from the expert."""
    errors = {}
    for weight in (0.0, 100.0):
        model, _ = built(tiny(bc_folder, bc_weight=weight, lr=3e-3, n_epochs=4))
        start = model.expert_action_mse()
        model.learn(64)
        errors[weight] = model.expert_action_mse()
    assert errors[100.0] < 0.9 * start < 0.9 * errors[0.0]


@pytest.mark.parametrize(("weight", "normalize"), [(0.0, False), (0.0, True), (1.0, False)])
def test_with_bc_weight_zero_an_update_is_ppos(bc_folder, weight, normalize):
    """From the same weights, optimiser state, rollout and random draws, BCRegularisedPPO.train with weight 0
    gives exactly the weights of stable-baselines3's PPO.train (with or without advantage normalisation); with
    weight 1 it does not."""
    import torch
    from stable_baselines3 import PPO

    model, venv = built(tiny(bc_folder, bc_weight=weight, n_epochs=2, normalize_advantage=normalize))
    model.learn(32)  # one rollout, one update: the buffer holds the rollout
    plain = PPO("MlpPolicy", venv, n_steps=8, batch_size=16, n_epochs=2, learning_rate=model.learning_rate,
                gamma=model.gamma, gae_lambda=model.gae_lambda, clip_range=0.2, seed=0, device="cpu",
                normalize_advantage=normalize, policy_kwargs={"net_arch": model.policy.net_arch})
    plain.policy.load_state_dict(copy.deepcopy(model.policy.state_dict()))
    plain.policy.optimizer.load_state_dict(copy.deepcopy(model.policy.optimizer.state_dict()))
    plain.rollout_buffer = model.rollout_buffer
    plain._current_progress_remaining = model._current_progress_remaining
    plain.set_logger(model.logger)
    for m in (model, plain):
        np.random.seed(7)
        torch.manual_seed(7)
        m.train()
    same = [torch.equal(a, b) for a, b in zip(model.policy.state_dict().values(), plain.policy.state_dict().values())]
    assert all(same) == (weight == 0.0)


def test_during_the_warm_up_only_the_critic_learns(bc_folder):
    import torch

    model, _ = built(tiny(bc_folder, critic_warmup_rollouts=2, bc_weight=1.0))  # 2 rollouts of 4 envs x 8 steps
    before = copy.deepcopy(model.policy.state_dict())
    model.learn(64)
    after = model.policy.state_dict()
    for name, value in after.items():
        moved = not torch.equal(before[name], value)
        assert moved == name.startswith(("value_net", "mlp_extractor.value_net")), name
    assert model.bc_config.bc_weight_at(64) == 0.0  # the weight the update used


def test_the_bc_weight_halves_every_half_life_after_the_warm_up(bc_folder):
    config = tiny(bc_folder, bc_weight=2.0, bc_half_life_frames=100, critic_warmup_rollouts=1)  # 32 env-steps
    assert [config.bc_weight_at(f) for f in (0, 32, 132, 232)] == [0.0, 0.0, 1.0, 0.5]
    assert tiny(bc_folder, bc_half_life_frames=None, bc_weight=3.0).bc_weight_at(10**9) == 3.0


def test_a_run_resumes_and_its_folder_flies_in_impact_env_run(bc_folder, tmp_path):
    from baselines.batched.bc_rl import run

    folder = tmp_path / "run"
    first = run(tiny(bc_folder, frames=32), folder, progress=False)
    assert first["env_steps"] == 32
    init = (folder / "init_evaluation.json").read_text()
    (folder / "result.json").unlink()  # as if the budget were raised after the first run
    for log in ("curve.jsonl", "updates.jsonl"):  # and a line written after the checkpoint, by a killed run
        (folder / log).write_text((folder / log).read_text() + json.dumps({"frames": 48}) + "\n")
    result = run(tiny(bc_folder, frames=64), folder, progress=False)
    assert result["env_steps"] == 64 and result["expert_pairs"] == 400
    for log in ("curve.jsonl", "updates.jsonl"):
        assert [json.loads(line)["frames"] for line in (folder / log).read_text().splitlines()] == [32, 64]
    assert (folder / "init_evaluation.json").read_text() == init  # the BC policy is flown once
    assert len(result["evaluation"]["pymunk"]["robustness"]) == 2 and "batched" not in result["evaluation"]
    assert not list(folder.glob("*.pkl"))
    meta = json.loads((folder / "train.json").read_text())
    assert meta["method"] == "BC+RL" and meta["timesteps_trained"] == 64 and meta["env_options"]["thrust_noise"] == 0.05
    with pytest.raises(ImpactEnvError, match="other settings .*bc_weight"):
        (folder / "result.json").unlink()
        run(tiny(bc_folder, frames=96, bc_weight=0.5), folder, progress=False)
    summary = tmp_path / "flown.json"
    assert main(["run", SCENARIO, "--controller", str(folder / "model.zip"), "--thrust-noise", "0.05",
                 "--initial-position-noise-m", "0.05", "--json", str(summary)]) == 0
    assert isinstance(json.loads(summary.read_text())["robustness"], float)


def test_the_cli_fine_tunes_and_prints_before_and_after(bc_folder, tmp_path, capsys):
    out = tmp_path / "cli"
    assert main(["bc-rl", SCENARIO, "--policy", str(bc_folder), "--out", str(out), "--frames", "32",
                 "--num-envs", "4", "--n-steps", "8", "--batch-size", "16", "--eval-episodes", "1",
                 "--critic-warmup-rollouts", "0", "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "BC policy" in printed and "after 32 env-steps" in printed and str(out / "model.zip") in printed
    assert json.loads((out / "result.json").read_text())["config"]["bc_half_life_frames"] == 1_000_000


def test_a_rollout_is_by_default_one_whole_episode_of_every_env(bc_folder):
    from baselines.batched.bc_rl import BcRlConfig

    config = BcRlConfig(SCENARIO, str(bc_folder), num_envs=4).with_horizon(200)
    assert (config.n_steps, config.batch_size, config.rollout_frames) == (200, 100, 800)  # 4 x 25 (25 divides 200)
    assert config.warmup_frames == 800 and config.chunk_frames == 131_200
    assert BcRlConfig(SCENARIO, str(bc_folder), n_steps=8, batch_size=16).with_horizon(200).n_steps == 8
    with pytest.raises(ImpactEnvError, match="batch_size must be a divisor"):
        BcRlConfig(SCENARIO, str(bc_folder), num_envs=4, batch_size=7).with_horizon(200)


def test_a_policy_of_another_scenario_is_refused(bc_folder):
    from gymnasium import spaces

    from baselines.batched.bc_rl import initial_policy
    from impact_env.errors import ModelFileError

    box = spaces.Box(-1.0, 1.0, shape=(3,), dtype=np.float32)
    with pytest.raises(ModelFileError, match="not on 'corridor'"):
        initial_policy(tiny(bc_folder).__class__("corridor", str(bc_folder)), box, box)


@pytest.mark.parametrize(("field", "value", "message"), [
    ("policy", "", "policy"), ("bc_weight", -1.0, "bc_weight"), ("bc_half_life_frames", 0, "bc_half_life_frames"),
    ("critic_warmup_rollouts", -1, "critic_warmup_rollouts"), ("bc_batch_size", 0, "bc_batch_size"),
    ("n_steps", 0, "n_steps"),
    ("log_std", float("nan"), "log_std"), ("lr", 0.0, "lr"), ("batch_size", 5, "batch_size"),
    ("reward_mode", "shaped", "reward_mode"), ("eval_batched_world", "no", "eval_batched_world"),
    ("normalize_advantage", 1, "normalize_advantage")])
def test_a_bad_config_is_a_typed_error_naming_the_field(field, value, message):
    from baselines.batched.bc_rl import BcRlConfig

    with pytest.raises(ImpactEnvError, match=f"BcRlConfig.{message}"):
        BcRlConfig(**{"scenario": SCENARIO, "policy": "runs/bc", **TINY, field: value})


def test_the_cli_checks_its_run_folder_and_its_policy_folder_before_training(tmp_path, capsys):
    from tests.helpers import one_line_error

    (tmp_path / "a_file").write_text("x")
    err = one_line_error(["bc-rl", SCENARIO, "--policy", str(tmp_path), "--out", str(tmp_path / "a_file")], capsys)
    assert "--out" in err and "is a file, not a folder" in err
    err = one_line_error(["bc-rl", SCENARIO, "--policy", str(tmp_path), "--out", str(tmp_path / "run")], capsys)
    assert "holds no model.zip" in err
