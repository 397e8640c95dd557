"""RL baselines: hyperparameter files, a short PPO run that saves, loads and flies through `impact-env run`,
and the PettingZoo parameter-sharing route."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from baselines import hyperparams
from baselines.train import TrainConfig, train
from impact_env.cli import main
from tests.optional import requires
from tests.paths import DATA
from tests.shipped_plans import path as committed_plan

pytestmark = requires("stable_baselines3", "supersuit")
MODELS = DATA / "models"  # copies of published folders of results/baselines/models/


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
    assert (run_dir / "model.zip").is_file() and (run_dir / "vecnormalize.json").is_file()
    assert list((run_dir / "tb").iterdir())  # TensorBoard logs
    assert json.loads((run_dir / "train.json").read_text())["timesteps"] == 2048
    out = tmp_path / "run.json"
    assert main(["run", "corridor", "--controller", str(run_dir / "model.zip"), "--json", str(out)]) == 0
    summary = json.loads(out.read_text())
    assert isinstance(summary["robustness"], float) and summary["episodes"][0]["steps"] == 1000
    # learning curves from the periodic evaluations (returns = the task's robustness)
    from baselines.curves import load_curve

    curve = load_curve(run_dir)
    assert curve.timesteps.tolist() == [1024, 2048] and curve.robustness.shape == (2, 1)
    assert -5.25 - 1e-6 <= curve.robustness.min() <= curve.robustness.max() <= 0.75 + 1e-6  # robustness bounds
    assert main(["curves", str(run_dir), "--out", str(tmp_path / "curves.png"), "--table", str(tmp_path / "t.md")]) == 0
    assert "| ppo (dense) | corridor | 2,048 |" in (tmp_path / "t.md").read_text()
    assert (tmp_path / "curves.png").stat().st_size > 1000
    (tmp_path / "empty").mkdir()
    assert main(["curves", str(tmp_path / "empty")]) == 2  # not a run folder: a clear error
    assert main(["curves", str(run_dir), "--labels", "a,b", "--out", str(tmp_path / "c.png")]) == 2


def test_pettingzoo_parameter_sharing_route(tmp_path):
    run_dir = train(TrainConfig(algo="ppo", scenario="throw_and_catch_exp", timesteps=1024, n_envs=1,
                                out=str(tmp_path), multiagent=True, progress_bar=False))
    assert json.loads((run_dir / "train.json").read_text())["multiagent"] is True
    from baselines.policy import SB3Controller
    from impact_env.transport.gym_env import TransportEnv

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


@pytest.fixture(scope="module")
def demonstrations(tmp_path_factory):
    """Three expert episodes of throw_and_catch_exp recorded through the CLI (with noise, so they differ), on
    the committed plan (tests/shipped_plans.py)."""
    pytest.importorskip("minari")
    out = tmp_path_factory.mktemp("datasets")
    plan = committed_plan("sr", "throw_and_catch_exp")
    assert main(["record", "throw_and_catch_exp", "--episodes", "3", "--out", str(out), "--plan", str(plan),
                 "--thrust-noise", "0.05", "--initial-position-noise-m", "0.03"]) == 0
    return out


def test_record_writes_a_minari_dataset(demonstrations):
    import minari

    ds = minari.load_dataset("impact_env/throw_and_catch_exp/expert-v0")
    assert ds.total_episodes == 3 and ds.total_steps == 600
    assert ds.spec.env_spec is not None and ds.spec.env_spec.id == "impact_env/ThrowAndCatchExp-v0"
    for ep in ds.iterate_episodes():
        assert ep.observations.shape == (201, 22) and ep.actions.shape == (200, 6)
        assert ep.rewards.sum() == pytest.approx(0.4, abs=0.05)  # dense rewards sum to the final robustness
        assert np.all(np.abs(ep.actions) <= 1.0)


def test_behaviour_cloning_fits_the_expert_and_flies(demonstrations, tmp_path):
    runs = tmp_path / "runs"
    # 80 epochs: the robust expert's actions are smaller and smoother (zero-action error 0.069), and 40 epochs
    # only got to a third of it (0.023); 80 get to an eighth (0.008)
    assert main(["bc", "throw_and_catch_exp", "--dataset", str(demonstrations), "--epochs", "80",
                 "--runs-dir", str(runs)]) == 0
    meta = json.loads((runs / "bc_throw_and_catch_exp_s0" / "train.json").read_text())
    assert meta["episodes_train"] == 2 and meta["episodes_validation"] == 1 and meta["samples"] == 400
    assert 1 <= meta["kept_epoch"] <= 80
    first, last = meta["history"][0], meta["history"][-1]
    assert last["nll"] < first["nll"]
    # the fitted policy reproduces the expert's actions far better than doing nothing would
    assert last["train_mse"] < 0.25 * meta["zero_action_mse"]
    out = tmp_path / "run.json"
    assert main(["run", "throw_and_catch_exp", "--controller", str(runs / "bc_throw_and_catch_exp_s0" / "model.zip"),
                 "--json", str(out)]) == 0
    assert isinstance(json.loads(out.read_text())["robustness"], float)

    # the benchmark takes a per-scenario model path and noise options; with noise the seeds differ
    bench = tmp_path / "bench"
    assert main(["bench", "throw_and_catch_exp", "--controllers", f"bc:{runs}/bc_{{scenario}}_s0/model.zip,zero",
                 "--episodes", "3", "--workers", "2", "--thrust-noise", "0.05", "--initial-position-noise-m", "0.05",
                 "--out", str(bench)]) == 0
    rows = list(__import__("csv").DictReader(open(bench / "episodes.csv")))
    assert [r["controller"] for r in rows] == ["bc"] * 3 + ["zero"] * 3
    assert len({r["robustness"] for r in rows if r["controller"] == "zero"}) == 3  # objects start apart
    assert "thrust_noise=0.05" in (bench / "summary.md").read_text()


def test_behaviour_cloning_is_deterministic(demonstrations, tmp_path):
    from baselines.bc import BCConfig, behaviour_clone

    histories = [json.loads((behaviour_clone(BCConfig("throw_and_catch_exp", str(demonstrations), epochs=3,
                                                      out=str(tmp_path / str(k)))) / "train.json").read_text())
                 ["history"] for k in range(2)]
    assert histories[0] == histories[1]


def test_behaviour_cloning_unpickles_nothing_and_writes_no_pickle(demonstrations, tmp_path):
    """Malicious pickles planted in the dataset folder and in bc's output folder (the payload would create a
    marker file) are never loaded; bc's model folder holds no pickle and flies without --trust-pickle."""
    import pickle

    from tests.baselines.test_model_safety import Payload, with_malicious_zip_entry

    marker = tmp_path / "marker"
    run_dir = tmp_path / "runs" / "bc_throw_and_catch_exp_s0"
    run_dir.mkdir(parents=True)
    for folder in (demonstrations, run_dir):
        (folder / "vecnormalize.pkl").write_bytes(pickle.dumps(Payload(marker)))
    shutil.copy(MODELS / "bc_throw_and_catch_exp" / "model.zip", demonstrations / "model.zip")
    with_malicious_zip_entry(demonstrations, marker, "evil")
    try:
        assert main(["bc", "throw_and_catch_exp", "--dataset", str(demonstrations), "--epochs", "2",
                     "--runs-dir", str(tmp_path / "runs")]) == 0
    finally:
        for name in ("vecnormalize.pkl", "model.zip"):
            (demonstrations / name).unlink()
    assert not marker.exists()
    assert sorted(p.name for p in run_dir.iterdir()) == ["model.zip", "train.json", "vecnormalize.json"]
    assert main(["run", "throw_and_catch_exp", "--controller", str(run_dir / "model.zip")]) == 0
    assert not marker.exists()


def test_behaviour_cloning_without_a_dataset_is_a_clear_error(tmp_path, capsys):
    pytest.importorskip("minari")
    assert main(["bc", "corridor", "--dataset", str(tmp_path / "empty")]) == 2
    assert "impact-env record corridor" in capsys.readouterr().err

def test_bench_rllib_specs_take_any_label_even_rllib():
    from baselines.bench import parse_controllers

    path = MODELS / "rllib_ppo_{scenario}"  # the published RLlib export
    specs = parse_controllers(f"rllib:{path},rl:rllib:{path},rllib:rllib:{path}", ["throw_and_catch_exp"])
    assert [(s.label, s.name, s.kind) for s in specs] == [("rllib", f"rllib:{path}", "rllib"),
                                                          ("rl", f"rllib:{path}", "rllib"),
                                                          ("rllib", f"rllib:{path}", "rllib")]


def test_bench_model_template_must_exist_for_every_scenario(tmp_path):
    from baselines.bench import parse_controllers
    from impact_env.errors import ImpactEnvError

    shutil.copytree(MODELS / "ppo_corridor", tmp_path / "corridor")
    spec, = parse_controllers(f"ppo:{tmp_path}/{{scenario}}/model.zip", ["corridor"])
    assert spec.label == "ppo"
    with pytest.raises(ImpactEnvError, match="obstacle_avoidance/model.zip"):
        parse_controllers(f"ppo:{tmp_path}/{{scenario}}/model.zip", ["corridor", "obstacle_avoidance"])
