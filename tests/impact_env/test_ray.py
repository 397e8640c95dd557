"""Sweeps and RLlib training on a local Ray instance (2 CPUs, one for this module, stopped at its end).

- a small bench (expert, an RLlib policy, random, zero) gives the same table on Ray tasks as on local
  processes, bit for bit (all but the controller's ms per step, a wall-clock measurement);
- two RLlib iterations with independent policies run, checkpoint, restore (resume), and the exported policy
  flies through ``impact-env run --controller rllib:RUN`` and acts exactly as RLlib's own restored module;
- errors on workers and files shared through the object store (shipping the code: test_ray_cluster.py).
"""

from __future__ import annotations

import csv
import json
import pickle
from pathlib import Path

import numpy as np
import pytest

from impact_env.cli import main
from impact_env.errors import EngineError, ScenarioError
from impact_env.sweep import EngineConfig, open_engine
from tests import sweep_jobs
from tests.optional import requires

# with --dist loadgroup: one Ray instance at a time in the suite
pytestmark = [requires("ray", "ray.rllib"), pytest.mark.xdist_group("ray")]

NOISE = ["--thrust-noise", "0.05", "--initial-position-noise-m", "0.05"]
TINY_PPO = """impact_env/ThrowAndCatchExp-v0:
  n_envs: 2
  n_timesteps: 800
  normalize: true
  n_steps: 200
  batch_size: 200
  n_epochs: 1
  learning_rate: lin_3e-4
  policy_kwargs: "dict(net_arch=[16, 16], log_std_init=-0.5)"
"""


@pytest.fixture(scope="module", autouse=True)
def local_ray():
    import ray

    ray.init(address="local", num_cpus=2, include_dashboard=False, logging_level="WARNING")
    yield
    ray.shutdown()


@pytest.fixture(scope="module")
def rllib_run(tmp_path_factory):
    """Two PPO iterations (2 x 400 env steps) with one policy per robot: the run folder."""
    root = tmp_path_factory.mktemp("rllib")
    (root / "tiny.yml").write_text(TINY_PPO)
    args = ["train", "ppo", "throw_and_catch_exp", "--engine", "rllib", "--policies", "independent",
            "--env-runners", "1", "--hyperparams", str(root / "tiny.yml"), "--eval-freq", "400", "--runs-dir",
            str(root / "runs"), *NOISE]
    assert main(args) == 0
    return root, args, root / "runs" / "rllib_ppo_throw_and_catch_exp_independent_s0"


def _without(path: Path, column: str) -> list[dict]:
    return [{k: v for k, v in row.items() if k != column} for row in csv.DictReader(open(path))]


def test_a_small_bench_gives_the_same_table_on_ray_as_on_local_processes(rllib_run, tmp_path, capsys):
    run = rllib_run[2]
    controllers = f"expert,rl:rllib:{run},random,zero"
    for engine in ("local", "ray"):
        assert main(["bench", "throw_and_catch_exp", "--controllers", controllers, "--episodes", "2", *NOISE,
                     "--engine", engine, "--workers", "2", "--out", str(tmp_path / engine)]) == 0
    out = capsys.readouterr().out
    assert "2 local worker processes: 9 jobs on 1 node" in out
    assert "Ray: 2 CPUs on 1 node (the Ray instance this process had started): 9 jobs on 1 node" in out
    local, on_ray = tmp_path / "local", tmp_path / "ray"
    episodes = _without(local / "episodes.csv", "controller_ms")
    assert episodes == _without(on_ray / "episodes.csv", "controller_ms")
    assert _without(local / "summary.csv", "ms_per_step") == _without(on_ray / "summary.csv", "ms_per_step")
    assert [r["controller"] for r in episodes] == ["expert"] * 2 + ["rl"] * 2 + ["random"] * 2 + ["zero"] * 2
    assert len({r["robustness"] for r in episodes if r["controller"] == "zero"}) == 2  # the seeds differ
    assert all(r["success"] == "True" for r in episodes if r["controller"] == "expert")
    assert json.loads((local / "plans" / "throw_and_catch_exp.json").read_text())["robustness"] == pytest.approx(0.4)
    from planners.plan import Plan

    plans = [Plan.load(folder / "plans" / "throw_and_catch_exp.json") for folder in (local, on_ray)]
    assert plans[0].fingerprint() == plans[1].fingerprint()  # planned on a Ray worker: the same plan, bit for bit


def test_rllib_iterations_checkpoint_restore_and_fly(rllib_run, tmp_path, capsys):
    root, args, run = rllib_run
    meta = json.loads((run / "train.json").read_text())
    assert meta["engine"] == "rllib" and meta["timesteps_trained"] == 800 and meta["agent_policies"] == {
        "R1": "R1", "R2": "R2"}
    policy = run / "checkpoint" / "policy"
    assert sorted(p.name for p in policy.iterdir()) == ["R1.npz", "R2.npz", "policy.json"]
    with np.load(policy / "R1.npz", allow_pickle=False) as weights:  # started at SB3's log_std_init
        assert np.all(np.abs(weights["pi.log_std"] + 0.5) < 0.05) and weights["pi.log_std"].shape == (3,)
    with np.load(run / "eval" / "evaluations.npz", allow_pickle=False) as ev:
        assert list(ev["timesteps"]) == [400, 800] and ev["results"].shape == (2, 5)

    # the exported policy is RLlib's own: the weights act alike, the observation filter has RLlib's statistics
    import torch
    from ray.rllib.core.rl_module.rl_module import RLModule
    from ray.rllib.utils.filter import RunningStat

    from baselines.rllib_policy import RLlibController
    from impact_env.transport.gym_env import TransportEnv
    from impact_env.transport.scenario import load_scenario

    scenario = load_scenario("throw_and_catch_exp")
    controller = RLlibController(scenario, run)
    # the env runners flew this scenario, not another with as many bodies: the object (third body in each
    # robot's observation) stayed on its line y = 0 of the 4 m x 3 m table (the corridor's is at y = 2 and up)
    mean_object_x, mean_object_y = controller.filters["R1"][0][14:16]
    assert 0.0 < mean_object_x < 4.0 and abs(mean_object_y) < 0.3, (mean_object_x, mean_object_y)
    filters = pickle.loads((run / "checkpoint" / "env_runner" / "env_to_module_connector" / "MeanStdFilter" /
                            "state.pkl").read_bytes())  # our own test run: trusted
    env = TransportEnv("throw_and_catch_exp", thrust_noise=0.05)
    obs, _ = env.reset(seed=3)
    for robot, x in controller.agent_observations(obs).items():
        (stat,) = [RunningStat.from_state(s) for s in filters[robot]["running_stats"]]
        assert stat.n >= 800
        np.testing.assert_allclose(controller.filters[robot][0], stat.mean, rtol=1e-6)
        theirs = RLModule.from_checkpoint(run / "checkpoint" / "learner_group" / "learner" / "rl_module" / robot)
        with torch.no_grad():
            expected = theirs.forward_inference({"obs": torch.from_numpy(x)[None]})["action_dist_inputs"]
            ours = controller.modules[robot].forward_inference({"obs": torch.from_numpy(x)[None]})["action_dist_inputs"]
        np.testing.assert_array_equal(ours.numpy(), expected.numpy())

    # restore: resuming loads RLlib's pickles, so only with --trust-pickle; then one more iteration
    (root / "tiny.yml").write_text(TINY_PPO.replace("n_timesteps: 800", "n_timesteps: 1200"))
    assert main(args + ["--resume"]) == 2
    assert "--trust-pickle" in capsys.readouterr().err
    assert main(args + ["--resume", "--trust-pickle"]) == 0
    meta = json.loads((run / "train.json").read_text())
    assert meta["timesteps_trained"] == 1200
    # one row per iteration, numbered on from the first run (3 iterations of 400 env steps at low load; on a busy
    # machine RLlib's env runners can return shorter samples, so more iterations reach the same 1,200)
    rows = list(csv.DictReader(open(run / "progress.csv")))
    assert [row["iteration"] for row in rows] == [str(k) for k in range(1, len(rows) + 1)] and len(rows) >= 3
    steps = [int(row["env_steps"]) for row in rows]
    assert steps == sorted(set(steps)) and 800 in steps and steps[-1] == 1200
    with np.load(run / "eval" / "evaluations.npz", allow_pickle=False) as ev:
        assert list(ev["timesteps"]) == [400, 800, 1200]

    # and it flies through impact-env run, deterministically
    out = tmp_path / "run.json"
    assert main(["run", "throw_and_catch_exp", "--controller", f"rllib:{run}", "--episodes", "2", *NOISE,
                 "--json", str(out)]) == 0
    episodes = json.loads(out.read_text())["episodes"]
    again = tmp_path / "again.json"
    assert main(["run", "throw_and_catch_exp", "--controller", f"rllib:{run}/checkpoint", "--episodes", "2", *NOISE,
                 "--json", str(again)]) == 0
    assert [e["robustness"] for e in episodes] == [e["robustness"] for e in json.loads(again.read_text())["episodes"]]
    assert all(e["steps"] == 200 for e in episodes)


def test_rllib_options_are_checked(tmp_path, capsys):
    assert main(["train", "sac", "corridor", "--engine", "rllib"]) == 2
    assert "--engine rllib trains ppo" in capsys.readouterr().err
    assert main(["train", "ppo", "corridor", "--env-runners", "2"]) == 2  # the sb3 engine has no env runners
    assert "--env-runners applies to --engine rllib" in capsys.readouterr().err
    assert main(["run", "corridor", "--controller", f"rllib:{tmp_path}"]) == 2
    assert "holds no exported RLlib policy" in capsys.readouterr().err


def test_errors_on_ray_workers_are_typed():
    with open_engine(EngineConfig("ray")) as engine:
        with pytest.raises(ScenarioError, match="job 2 is a bad scenario"):
            list(engine.map(sweep_jobs.fail_on, [0, 1, 2]))
        with pytest.raises(EngineError, match=r"job 4 of 4 failed on a Ray worker: ZeroDivisionError"):
            list(engine.map(sweep_jobs.fail_on, [0, 1, 1, 3]))
        assert list(engine.map(sweep_jobs.threads, [None])) == [{"omp": "1", "torch": 1}]


def test_shared_files_reach_ray_workers_by_content(tmp_path):
    folder = tmp_path / "model"
    folder.mkdir()
    (folder / "model.zip").write_bytes(b"weights v1")
    (folder / "checkpoint.bin").write_bytes(b"not needed")
    with open_engine(EngineConfig("ray")) as engine:
        handle = engine.share(folder, include=["model.zip"])
        (first,) = engine.map(sweep_jobs.read_shared, [(handle, "model.zip")])
        assert first["bytes"] == b"weights v1" and first["path"] != str(folder)  # a copy, not the driver's path
        assert not (Path(first["path"]) / "checkpoint.bin").exists()
        (folder / "model.zip").write_bytes(b"weights v2")  # new contents: a new copy
        (second,) = engine.map(sweep_jobs.read_shared, [(engine.share(folder, include=["model.zip"]), "model.zip")])
        assert second["bytes"] == b"weights v2" and second["path"] != first["path"]


def test_ship_code_needs_its_own_ray_connection():
    with pytest.raises(EngineError, match="--ship-code needs to start the Ray connection itself"):
        open_engine(EngineConfig("ray", ship_code=True))


def test_a_list_of_scenarios_plans_alike_on_ray_and_on_local_processes(tmp_path, capsys):
    from planners.plan import Plan

    names = "throw_and_catch_exp,corridor"
    for engine in ("local", "ray"):
        assert main(["plan", names, "--engine", engine, "--workers", "2", "--out", str(tmp_path / engine)]) == 0
    assert "planning 2 scenarios on Ray: 2 CPUs" in capsys.readouterr().out
    for name in names.split(","):
        local, on_ray = (Plan.load(tmp_path / e / f"{name}.json") for e in ("local", "ray"))
        assert local.fingerprint() == on_ray.fingerprint() and local.robustness > 0
