"""The residual policy (baselines/residual/) on throw_and_catch_exp (200 steps an episode): the wrapper's spaces, a
zero correction flies the expert's own episode, clipping, training's save/load round trip and resume, the CLI."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from impact_env.cli import main
from impact_env.errors import EnvConfigError, ImpactEnvError
from tests.optional import requires
from tests.shipped_plans import path as committed_plan

pytestmark = requires("stable_baselines3")
SCENARIO = "throw_and_catch_exp"
NOISE = {"impact_velocity_noise_mps": 0.02, "thrust_noise": 0.05, "initial_position_noise_m": 0.05}


def _plan() -> str:
    return str(committed_plan("sr", SCENARIO))


def _env(scale: float = 0.2, action_penalty: float = 0.0):
    from baselines.residual import ResidualEnv, build_expert
    from impact_env.transport.gym_env import TransportEnv

    return ResidualEnv(TransportEnv(SCENARIO, **NOISE), build_expert(SCENARIO, _plan(), "all"), scale, action_penalty)


def _config(tmp_path, **changes):
    from baselines.residual import ResidualConfig

    base = ResidualConfig(SCENARIO, plan=_plan(), timesteps=128, n_steps=64, batch_size=32, n_epochs=2,
                          save_every=64, out=str(tmp_path / "run"), quiet=True)
    return dataclasses.replace(base, **changes)


def test_the_wrapper_passes_gymnasium_and_sb3_env_checks():
    from gymnasium.utils.env_checker import check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = _env()
    check_env(env, skip_render_check=True)
    sb3_check_env(env, warn=True)
    n_obs = env.env.observation_space.shape[0]
    assert env.observation_space.shape == (n_obs + 6,) and env.action_space.shape == (6,)
    obs, info = env.reset(seed=1)
    np.testing.assert_array_equal(obs[n_obs:], info["expert_action"])  # the agent sees the command it corrects


def test_a_zero_correction_flies_the_expert_episode_exactly():
    """Same seed, noise on: the residual world with a = 0 executes the expert's own actions, step for step,
    and ends with the same robustness; the reward is the env's (no penalty for a zero correction)."""
    from impact_env.transport.gym_env import TransportEnv
    from planners.expert import Expert
    from planners.plan import Plan

    env, expert = TransportEnv(SCENARIO, **NOISE), Expert(SCENARIO, plan=Plan.load(_plan()))
    obs, info = env.reset(seed=4)
    expert.reset(env, 4)
    own_obs, own_actions, own_rewards, done = [obs], [], [], False
    while not done:
        action = expert.act(obs, info)
        obs, reward, terminated, truncated, info = env.step(action)
        own_obs.append(obs), own_actions.append(action), own_rewards.append(reward)
        done = terminated or truncated
    own_robustness = info["robustness"]

    residual = _env(action_penalty=1.0)
    obs, info = residual.reset(seed=4)
    n_obs, k, done = own_obs[0].shape[0], 0, False
    np.testing.assert_array_equal(obs[:n_obs], own_obs[0])
    while not done:
        obs, reward, terminated, truncated, info = residual.step(np.zeros(6, np.float32))
        np.testing.assert_array_equal(info["executed_action"], own_actions[k])
        np.testing.assert_array_equal(obs[:n_obs], own_obs[k + 1])
        assert reward == own_rewards[k]
        k, done = k + 1, terminated or truncated
    assert k == len(own_actions) == 200 and info["robustness"] == own_robustness


def test_corrections_are_clipped_and_scaled():
    from baselines.residual import compose

    command = np.array([0.9, -0.95, 0.0], np.float32)
    np.testing.assert_allclose(compose(command, np.array([1.0, -1.0, 0.5]), 0.2), [1.0, -1.0, 0.1], atol=1e-7)
    np.testing.assert_allclose(compose(command, np.array([5.0, 5.0, -7.0]), 0.2), [1.0, -0.75, -0.2], atol=1e-7)
    env = _env(scale=0.5, action_penalty=0.1)
    _, info = env.reset(seed=0)
    command = info["expert_action"]
    _, reward, _, _, info = env.step(np.full(6, 3.0, np.float32))
    np.testing.assert_array_equal(info["residual"], np.ones(6))
    np.testing.assert_allclose(info["executed_action"], np.clip(command + 0.5, -1, 1), atol=1e-6)
    with pytest.raises(EnvConfigError, match="scale"):
        _env(scale=0.0)
    with pytest.raises(EnvConfigError, match="action_penalty"):
        _env(action_penalty=-1.0)


def test_training_saves_a_safe_model_that_loads_back_and_resumes(tmp_path):
    """The run folder loads without unpickling and predicts what SB3's own loader predicts; the first policy's mean
    correction is zero; a resumed run continues the step count, and other settings are refused."""
    from stable_baselines3 import PPO

    from baselines.model_files import load_normalization
    from baselines.residual import ResidualController, build_expert, train_residual

    run = train_residual(_config(tmp_path, timesteps=64))
    fresh = ResidualController(build_expert(SCENARIO, _plan(), "all"), run)
    x = np.zeros(fresh.model.observation_space.shape, np.float32)
    assert np.abs(fresh.model.predict(x, deterministic=True)[0]).max() < 0.05  # one small update from zero
    train_residual(_config(tmp_path, resume=True))
    meta = json.loads((run / "train.json").read_text())
    assert meta["timesteps_trained"] == 128 and [c["env_steps"] for c in meta["chunks"]] == [64, 128]
    assert meta["method"] == "residual" and meta["env_options"] == NOISE

    controller = ResidualController(build_expert(SCENARIO, _plan(), "all"), run)
    trusted = PPO.load(str(run / "model.zip"), device="cpu")  # our own file: SB3's loader may unpickle it
    norm = load_normalization(run, x.shape[0])
    env = _env()
    obs, info = env.reset(seed=2)
    controller.reset(env.env, 2)
    for _ in range(5):
        action = controller.act(obs[:-6], info)
        expected = trusted.predict(norm.apply(obs), deterministic=True)[0]
        np.testing.assert_allclose(controller.residuals[-1], np.clip(expected, -1, 1), atol=1e-6)
        np.testing.assert_allclose(action, np.clip(info["expert_action"] + 0.2 * controller.residuals[-1], -1, 1),
                                   atol=1e-6)
        obs, _, _, _, info = env.step(controller.residuals[-1])  # the same world: env's expert, same history

    with pytest.raises(ImpactEnvError, match="scale"):
        train_residual(_config(tmp_path, scale=0.5, resume=True, timesteps=192))
    with pytest.raises(ImpactEnvError, match="--resume"):
        train_residual(_config(tmp_path))


def test_cli_errors_are_one_line(tmp_path, capsys):
    out = str(tmp_path / "run")
    assert main(["residual", SCENARIO, "--scale", "0", "--out", out]) == 2
    assert "ResidualConfig.scale must be" in capsys.readouterr().err
    assert main(["residual", "no_such_scenario", "--out", out]) == 2
    assert "unknown scenario" in capsys.readouterr().err
    assert main(["residual", SCENARIO, "--resume", "--plan", _plan(), "--out", out]) == 2
    assert "holds no residual run" in capsys.readouterr().err
    assert main(["residual", SCENARIO, "--impact-velocity-noise-mps", "-1", "--plan", _plan(), "--out", out]) == 2
    assert "impact_velocity_noise_mps" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["residual", SCENARIO, "--stack", "best"])
    with pytest.raises(SystemExit):
        main(["residual", "--help"])
    assert "post-impact velocity noise" in capsys.readouterr().out


def test_cli_trains_with_progress_lines(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["residual", SCENARIO, "--plan", _plan(), "--timesteps", "64", "--save-every", "64", "--out",
                 str(out)]) == 0
    text = capsys.readouterr().out
    assert "env-steps" in text and "saved" in text and (out / "vecnormalize.json").is_file()


def test_the_benchmark_pairs_the_same_seeds():
    from benchmarks.residual import compare, mcnemar

    expert = np.array([True, True, False, False, True])
    residual = np.array([True, False, True, True, True])
    m = mcnemar(expert, residual)
    assert (m["only_residual"], m["only_expert"]) == (2, 1)
    assert m["p_two_sided"] == pytest.approx(1.0) and m["p_residual_better"] == pytest.approx(0.5)
    cells = [{"episodes": [{"seed": s, "success": bool(v), "robustness": float(v)} for s, v in enumerate(arr)]}
             for arr in (expert, residual)]
    cmp = compare(cells[0], cells[1])
    assert (cmp["expert_successes"], cmp["residual_successes"]) == (3, 4)
    assert cmp["robustness_diff_ci"][0] <= 0.2 <= cmp["robustness_diff_ci"][1]


def test_cells_flown_with_an_earlier_expert_are_marked_and_flown_again(tmp_path):
    """A cell records the expert config it was flown with; one from another config, or from before cells recorded
    it, is not today's comparison: the table marks it, and the benchmark flies it again."""
    import json

    from benchmarks.residual import current, expert_config_now, table
    from benchmarks.robustness import SAME_FLIGHTS

    now = expert_config_now()
    assert current({"config": now}) and not current({}) and not current(None)
    assert current({"config": next(old for old, new in SAME_FLIGHTS.items() if new == now)})
    assert not current({"config": "000000000000"})

    def cell(controller, config=None, seed=-1):
        out = {"scenario": "corridor", "controller": controller, "train_seed": seed, "train_env_steps": 10,
               "train_wall_s": 60.0, "episodes": [{"seed": k, "success": True, "robustness": 0.1,
                                                   "ms_per_step": 1.0} for k in range(3)]}
        return out if config is None else {**out, "config": config}

    (tmp_path / "cells.jsonl").write_text("".join(json.dumps(c) + "\n" for c in
                                                  [cell("expert", now), cell("residual", now, 0),
                                                   cell("residual", None, 1)]))
    text = table(tmp_path)
    assert "| corridor | 0 |" in text and "| corridor * | 1 |" in text and "flown with an earlier expert" in text


def test_the_controller_refuses_a_folder_without_a_residual_policy(tmp_path):
    from baselines.residual import ResidualController, build_expert
    from impact_env.errors import ControllerError

    (tmp_path / "model.zip").write_bytes(b"PK")
    (tmp_path / "train.json").write_text(json.dumps({"algo": "ppo", "method": "DAgger"}))
    with pytest.raises(ControllerError, match="no residual policy"):
        ResidualController(build_expert(SCENARIO, _plan(), "all"), tmp_path)
