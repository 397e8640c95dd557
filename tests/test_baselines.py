"""RL baselines: hyperparameter files, a short PPO run that saves, loads and flies through `impact-env run`,
and the PettingZoo parameter-sharing route."""

from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")
pytest.importorskip("supersuit")

from baselines import hyperparams  # noqa: E402
from baselines.train import TrainConfig, train  # noqa: E402
from impact_env.cli import main  # noqa: E402


def test_hyperparameter_files_parse_without_eval():
    for algo in ("ppo", "sac"):
        for env_id in ("impact_env/Corridor-v0", "impact_env/ObstacleAvoidance-v0", "impact_env/ThrowAndCatchExp-v0"):
            entry = hyperparams.load(algo, env_id)
            assert entry["policy"] == "MlpPolicy" and entry["n_timesteps"] > 0
            assert isinstance(entry["policy_kwargs"], dict)
    lr = hyperparams.load("ppo", "impact_env/Corridor-v0")["learning_rate"]
    assert lr(1.0) == pytest.approx(3e-4) and lr(0.5) == pytest.approx(1.5e-4)
    with pytest.raises(hyperparams.HyperparameterError, match="not a literal"):
        hyperparams.parse_policy_kwargs("dict(net_arch=__import__('os').system('true'))")
    with pytest.raises(hyperparams.HyperparameterError, match="dict"):
        hyperparams.parse_policy_kwargs("[1, 2]")


def test_ppo_smoke_train_save_load_and_run(tmp_path):
    run_dir = train(TrainConfig(algo="ppo", scenario="corridor", timesteps=2048, n_envs=2, out=str(tmp_path),
                                eval_freq=1024, eval_episodes=1, progress_bar=False))
    assert (run_dir / "model.zip").is_file() and (run_dir / "vecnormalize.pkl").is_file()
    assert list((run_dir / "tb").iterdir())  # TensorBoard logs
    assert json.loads((run_dir / "train.json").read_text())["timesteps"] == 2048
    out = tmp_path / "run.json"
    assert main(["run", "corridor", "--controller", str(run_dir / "model.zip"), "--json", str(out)]) == 0
    summary = json.loads(out.read_text())
    assert isinstance(summary["robustness"], float) and summary["episodes"][0]["steps"] == 1000


def test_pettingzoo_parameter_sharing_route(tmp_path):
    run_dir = train(TrainConfig(algo="ppo", scenario="throw_and_catch_exp", timesteps=1024, n_envs=1,
                                out=str(tmp_path), multiagent=True, progress_bar=False))
    assert json.loads((run_dir / "train.json").read_text())["multiagent"] is True
    from baselines.policy import SB3Controller
    from impact_env.envs.transport import TransportEnv

    env = TransportEnv("throw_and_catch_exp")
    controller = SB3Controller(env.scenario, run_dir / "model.zip")
    obs, info = env.reset(seed=0)
    controller.reset(env, 0)
    action = controller.act(obs, info)
    assert action.shape == (6,) and np.all(np.abs(action) <= 1.0 + 1e-6)


def test_missing_model_is_a_clear_error(tmp_path, capsys):
    assert main(["run", "corridor", "--controller", str(tmp_path / "nope.zip")]) == 2
    assert "does not exist" in capsys.readouterr().err


def test_bench_writes_tables_and_figure(tmp_path):
    out = tmp_path / "bench"
    code = main(["bench", "throw_and_catch_exp", "--controllers", "expert,zero", "--episodes", "1",
                 "--workers", "1", "--out", str(out)])
    assert code == 0
    rows = {r["controller"]: r for r in __import__("csv").DictReader(open(out / "summary.csv"))}
    assert float(rows["expert"]["success_rate"]) == 1.0 and float(rows["zero"]["success_rate"]) == 0.0
    assert float(rows["zero"]["robustness_mean"]) == pytest.approx(-0.6, abs=1e-6)
    assert "| throw_and_catch_exp | expert |" in (out / "summary.md").read_text()
    assert (out / "bench.png").stat().st_size > 1000 and (out / "episodes.csv").is_file()


def test_bench_rejects_a_missing_model(tmp_path, capsys):
    assert main(["bench", "corridor", "--controllers", f"ppo:{tmp_path / 'none.zip'}", "--out", str(tmp_path)]) == 2
    assert "does not exist" in capsys.readouterr().err


def test_record_writes_a_minari_dataset(tmp_path):
    pytest.importorskip("minari")
    out = tmp_path / "datasets"
    assert main(["record", "throw_and_catch_exp", "--episodes", "2", "--out", str(out)]) == 0
    import minari

    ds = minari.load_dataset("impact_env/throw_and_catch_exp/expert-v0")
    assert ds.total_episodes == 2 and ds.total_steps == 400
    assert ds.spec.env_spec is not None and ds.spec.env_spec.id == "impact_env/ThrowAndCatchExp-v0"
    for ep in ds.iterate_episodes():
        assert ep.observations.shape == (201, 22) and ep.actions.shape == (200, 6)
        assert ep.rewards.sum() == pytest.approx(0.4, abs=0.02)  # dense rewards sum to the final robustness
