"""RL at scale (benchmarks/rl_at_scale.py, baselines/batched/sb3_ppo.py, benchmarks/rl_at_scale_report.py) at
tiny sizes: the SB3 trainer's checkpoints and resume, the queue's order, states and extension, publishing
through CellStore, and the rliable report on cells with known scores. No test trains for real: a run here is
4 envs for a few dozen env-steps."""

from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pytest

from benchmarks import rl_at_scale
from benchmarks.rl_at_scale import Run, cell_key, publish, queue, run_one, status
from impact_env.errors import ImpactEnvError
from tests.optional import requires
from tests.paths import ROOT

if TYPE_CHECKING:
    from baselines.batched.sb3_ppo import Sb3PpoConfig

# SB3 (and torch) looked up, not imported, while the suite is collected: the tests import the trainer when they run
pytestmark = requires("stable_baselines3")

SCENARIO = "throw_and_catch_exp"  # the shortest horizon (200 steps): the final evaluation stays cheap
TINY = {"num_envs": 4, "n_steps": 8, "batch_size": 16, "n_epochs": 1, "checkpoint_frames": 32, "eval_episodes": 2,
        "hidden": (8,)}


def tiny(frames: int, seed: int = 0, **kw) -> Sb3PpoConfig:
    from baselines.batched.sb3_ppo import Sb3PpoConfig

    return Sb3PpoConfig(SCENARIO, seed=seed, frames=frames, **{**TINY, **kw})


def run(config: Sb3PpoConfig, folder: Path, **kw):
    """baselines.batched.sb3_ppo.run, imported when a test trains."""
    from baselines.batched.sb3_ppo import run as train

    return train(config, folder, **kw)


def curve_frames(folder: Path) -> list[int]:
    return [json.loads(line)["frames"] for line in (folder / "curve.jsonl").read_text().splitlines() if line]


@pytest.fixture(scope="module")
def trained(tmp_path_factory) -> Path:
    """A finished tiny run of 64 env-steps (two checkpoints of 32)."""
    folder = tmp_path_factory.mktemp("runs") / "sb3_ppo__throw_and_catch_exp__s0"
    run(tiny(64), folder, progress=False)
    return folder


def test_sb3_run_writes_checkpoints_curve_and_evaluation(trained):
    result = json.loads((trained / "result.json").read_text())
    assert result["env_steps"] == 64 and result["budget_env_steps"] == 64
    assert curve_frames(trained) == [32, 64]  # one line per rollout of 4 envs x 8 steps
    assert json.loads((trained / "state.json").read_text())["frames"] == 64
    train = json.loads((trained / "train.json").read_text())
    assert train["algo"] == "ppo" and train["timesteps_trained"] == 64 and train["env_options"]["thrust_noise"] == 0.05
    for world in ("batched", "pymunk"):
        ev = result["evaluation"][world]
        assert len(ev["robustness"]) == 2
        assert ev["success_rate"] == np.mean(np.array(ev["robustness"]) > 0)
    assert not list(trained.glob("*.pkl"))  # the model folder is pickle-free


def test_sb3_model_folder_loads_as_a_bench_controller(trained):
    """impact-env bench reads the checkpoint (no pickle) and flies it on the pymunk env."""
    from impact_env.controllers import make_controller
    from impact_env.transport.gym_env import TransportEnv
    from impact_env.transport.scenario import load_scenario

    controller = make_controller(str(trained / "model.zip"), load_scenario(SCENARIO))
    env = TransportEnv(SCENARIO, thrust_noise=0.05, initial_position_noise_m=0.05)
    obs, info = env.reset(seed=3)
    controller.reset(env, 3)
    action = controller.act(obs, info)
    assert action.shape == env.action_space.shape and np.all(np.abs(action) <= 1.0)


def test_sb3_run_resumes_from_its_last_checkpoint(tmp_path):
    folder = tmp_path / "r"
    run(tiny(32), folder, progress=False)
    before = (folder / "model.zip").read_bytes()
    (folder / "result.json").unlink()  # as if killed after the checkpoint at 32 env-steps
    (folder / "curve.jsonl").write_text((folder / "curve.jsonl").read_text() + json.dumps({"frames": 48}) + "\n")
    result = run(tiny(64), folder, progress=False)
    assert result["env_steps"] == 64
    assert curve_frames(folder) == [32, 64]  # the line after the checkpoint was dropped, none repeated
    assert (folder / "model.zip").read_bytes() != before


def test_sb3_run_refuses_a_folder_of_other_settings(tmp_path, trained):
    folder = tmp_path / "r"
    shutil.copytree(trained, folder)
    (folder / "result.json").unlink()
    with pytest.raises(ValueError, match="other settings .*n_epochs"):
        run(tiny(96, n_epochs=2), folder, progress=False)


def test_sb3_config_errors():
    from baselines.batched.sb3_ppo import Sb3PpoConfig

    with pytest.raises(ImpactEnvError, match=r"Sb3PpoConfig\.batch_size must be a divisor of num_envs x n_steps "
                                             r"\(4 x 8 = 32\), got 5"):
        Sb3PpoConfig(SCENARIO, num_envs=4, n_steps=8, batch_size=5)
    with pytest.raises(ImpactEnvError, match="Sb3PpoConfig.frames must be an integer >= 1, got 0"):
        Sb3PpoConfig(SCENARIO, frames=0)


def test_marl_config_errors_and_the_config_needs_no_benchmarl():
    import subprocess

    from baselines.batched.marl import MarlConfig

    with pytest.raises(ImpactEnvError, match=r"MarlConfig\.frames_per_batch must be a multiple of num_envs \(512\), "
                                             r"got 1000"):
        MarlConfig("mappo", "corridor", frames_per_batch=1000)
    with pytest.raises(ImpactEnvError, match=r"MarlConfig\.checkpoint_frames must be a multiple of frames_per_batch"):
        MarlConfig("mappo", "corridor", checkpoint_frames=1000)
    with pytest.raises(ImpactEnvError, match="MarlConfig.algorithm must be one of mappo, ippo, got 'qmix'"):
        MarlConfig("qmix", "corridor")
    # benchmarl is an optional extra: the module and its config import without it
    code = ("import sys; sys.modules['benchmarl'] = None; from baselines.batched.marl import MarlConfig; "
            "print(MarlConfig('ippo', 'corridor').algorithm)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert done.returncode == 0 and done.stdout.strip() == "ippo", done.stderr


def test_queue_goes_seed_by_seed_and_rejects_unknown_kinds():
    runs = queue(["sb3", "mappo"], [0, 1], 100, ["corridor", "relay"])
    assert [r.name for r in runs[:4]] == ["sb3_ppo__corridor__s0", "mappo__corridor__s0", "sb3_ppo__relay__s0",
                                          "mappo__relay__s0"]
    assert {r.seed for r in runs[4:]} == {1}
    vmas = queue(["vmas"], [0], 100, ["corridor"])
    assert [r.name for r in vmas] == ["mappo__vmas_transport__s0", "ippo__vmas_transport__s0"]
    with pytest.raises(ValueError, match="unknown kinds ppo"):
        queue(["ppo"], [0], 100, ["corridor"])
    command = Run("sb3_ppo", "corridor", 2, 100, trainer_args=("--num-envs", "4")).command("py", Path("f"), 1)
    assert command[:4] == ["py", "-m", "baselines.batched.sb3_ppo", "corridor"] and command[-2:] == ["--num-envs", "4"]


def test_status_and_publish(tmp_path, trained):
    runs_dir = tmp_path / "runs"
    shutil.copytree(trained, runs_dir / trained.name)
    assert status(Run("sb3_ppo", SCENARIO, 0, 64), runs_dir) == ("done", 64)
    assert status(Run("sb3_ppo", SCENARIO, 0, 128), runs_dir) == ("extend", 64)
    assert status(Run("sb3_ppo", SCENARIO, 1, 64), runs_dir) == ("pending", 0)
    partial = runs_dir / "sb3_ppo__throw_and_catch_exp__s1"
    partial.mkdir()
    shutil.copy(trained / "curve.jsonl", partial / "curve.jsonl")
    assert status(Run("sb3_ppo", SCENARIO, 1, 64), runs_dir) == ("partial", 64)
    out = tmp_path / "out"
    cells = publish(runs_dir, out, report=False)
    assert [cell_key(c) for c in cells] == [("sb3_ppo", SCENARIO, 0)]
    assert cells[0]["run"] == trained.name and cells[0]["env_steps"] == 64
    first = (out / "cells.jsonl").read_bytes()
    publish(runs_dir, out, report=False)
    assert (out / "cells.jsonl").read_bytes() == first  # publishing again changes nothing
    assert sorted(p.name for p in (out / "curves").iterdir()) == [f"{trained.name}.jsonl", f"{partial.name}.jsonl"]


def test_status_markdown_says_what_ran_and_what_remains(tmp_path, trained):
    runs_dir = tmp_path / "runs"
    shutil.copytree(trained, runs_dir / trained.name)
    runs = queue(["sb3"], [0, 1], 64, [SCENARIO])
    text = rl_at_scale.status_markdown(runs, runs_dir, "python -m benchmarks.rl_at_scale --frames 64")
    assert "1 of the 2 runs of `python -m benchmarks.rl_at_scale --frames 64` finished" in text
    assert "What remains:** sb3_ppo__throw_and_catch_exp__s1." in text


def test_run_one_skips_a_finished_run_and_extends_a_smaller_budget(tmp_path, trained):
    runs_dir = tmp_path / "runs"
    shutil.copytree(trained, runs_dir / trained.name)
    args = ("--num-envs", "4", "--n-steps", "8", "--batch-size", "16", "--n-epochs", "1", "--checkpoint-frames",
            "32", "--eval-episodes", "2")
    done = Run("sb3_ppo", SCENARIO, 0, 64, trainer_args=args)
    assert run_one(done, runs_dir, tmp_path / "logs", sys.executable, None, 1).endswith("done before")
    skipped = Run("mappo", rl_at_scale.VMAS_TASK, 0, 64)
    assert "skipped" in run_one(skipped, runs_dir, tmp_path / "logs", sys.executable, None, 1)


@pytest.mark.slow
def test_run_one_extends_a_finished_run_in_a_subprocess(tmp_path, trained):
    runs_dir = tmp_path / "runs"
    shutil.copytree(trained, runs_dir / trained.name)
    # the fixture's run used hidden (8,); the command line has no --hidden, so start a fresh tiny run
    shutil.rmtree(runs_dir / trained.name)
    args = ("--num-envs", "4", "--n-steps", "8", "--batch-size", "16", "--n-epochs", "1", "--checkpoint-frames",
            "32", "--eval-episodes", "1")
    first = Run("sb3_ppo", SCENARIO, 0, 32, trainer_args=args)
    assert "finished" in run_one(first, runs_dir, tmp_path / "logs", sys.executable, None, 1)
    more = Run("sb3_ppo", SCENARIO, 0, 64, trainer_args=args)
    assert "finished" in run_one(more, runs_dir, tmp_path / "logs", sys.executable, None, 1)
    folder = runs_dir / first.name
    assert json.loads((folder / "result_32.json").read_text())["env_steps"] == 32
    assert json.loads((folder / "result.json").read_text())["env_steps"] == 64
    assert curve_frames(folder) == [32, 64]
    assert "resuming" in (tmp_path / "logs" / f"{first.name}.log").read_text()


# ------------------------------------------------------------------------------------------------- the report
def synthetic_cell(algorithm: str, task: str, seed: int, success: float, robustness: float) -> dict:
    """A cell as rl_at_scale publishes it, with a chosen pymunk success rate and robustness."""
    return {"algorithm": algorithm, "task": task, "seed": seed, "env_steps": 1000, "budget_env_steps": 1000,
            "wall_s": 60.0 * (seed + 1), "env_steps_per_s": 100.0, "run": f"{algorithm}__{task}__s{seed}",
            "evaluation": {"episodes": 10, "batched": {"success_rate": success, "robustness_mean": robustness},
                           "pymunk": {"success_rate": success, "robustness_mean": robustness}}}


def test_report_interquartile_means_and_files(tmp_path):
    pytest.importorskip("rliable")
    from benchmarks.rl_at_scale_report import aggregate, markdown, write_report
    from impact_env.results_store import CellStore

    successes = {"a": [0.0, 0.2, 0.4, 1.0], "b": [1.0, 1.0, 1.0, 1.0]}
    cells = [synthetic_cell("sb3_ppo", task, seed, s, s - 0.5) for task, values in successes.items()
             for seed, s in enumerate(values)]
    cells.append(synthetic_cell("mappo", "a", 0, 0.5, 0.0))  # one seed of one task only
    # MAPPO is scored by its sampled actions (0.9 here), its deterministic 0.5 shown beside
    cells[-1]["evaluation"]["sampled"] = {"batched": {"success_rate": 0.8, "robustness_mean": 0.1},
                                          "pymunk": {"success_rate": 0.9, "robustness_mean": 0.2}}
    numbers = aggregate(cells, reps=50)
    rows = {(r["algorithm"], r["task"]): r for r in numbers["rows"]}
    a = rows[("sb3_ppo", "a")]
    assert a["success_iqm"] == pytest.approx(0.3)  # the middle half of 0, 0.2, 0.4, 1
    assert a["success_ci"][0] <= 0.3 <= a["success_ci"][1]
    assert a["robustness_iqm"] == pytest.approx(-0.2)
    assert rows[("sb3_ppo", "b")]["success_ci"] == [1.0, 1.0]
    assert a["seeds"] == [0, 1, 2, 3] and a["budget_env_steps"] == [1000] and a["wall_s"] == [60, 120, 180, 240]
    overall = {o["algorithm"]: o for o in numbers["overall"]}
    # runs x tasks: 0, 0.2, 0.4, 1, 1, 1, 1, 1 -> the middle half is 0.4, 1, 1, 1
    assert overall["sb3_ppo"]["iqm"] == pytest.approx(0.85)
    assert overall["sb3_ppo"]["mean"] == pytest.approx(np.mean(successes["a"] + successes["b"]))
    assert overall["sb3_ppo"]["tasks"] == ["a", "b"] and overall["sb3_ppo"]["seeds"] == [0, 1, 2, 3]
    assert overall["mappo"]["seeds"] == [0] and overall["mappo"]["iqm"] == pytest.approx(0.9)
    assert rows[("mappo", "a")]["policy"] == ["sampled"] and rows[("mappo", "a")]["deterministic_success"] == [0.5]
    assert rows[("mappo", "a")]["batched_success"] == [0.8] and rows[("mappo", "a")]["robustness"] == [0.2]
    assert numbers["transfer"]["max_abs_points"] == pytest.approx(10)  # mappo's sampled 0.8 against 0.9
    assert numbers["transfer"]["differ_at_0_01"] == []  # 8 of 10 against 9 of 10 is no evidence of a difference
    text = markdown(numbers)
    assert "| a | sb3_ppo | 0,1,2,3 | 1k | 2.5 | 100 | 10 | deterministic |" in text and "0 / 20 / 40 / 100" in text
    assert "| a | mappo | 0 | 1k | 1.0 | 100 | 10 | sampled | 90 [90, 90] | 90 | 80 | 50 |" in text

    store = CellStore(tmp_path / "cells.jsonl", cell_key)
    for cell in cells:
        store.put(cell)
    (tmp_path / "curves").mkdir()
    (tmp_path / "curves" / "sb3_ppo__a__s0.jsonl").write_text(
        "".join(json.dumps({"frames": f, "wall_s": f / 10, "success_rate": f / 1000}) + "\n" for f in (500, 1000)))
    write_report(tmp_path, reps=50)
    for name in ("summary.md", "summary.json", "curves_steps.png", "curves_wall.png", "profile.png"):
        assert (tmp_path / name).stat().st_size > 0, name
    assert json.loads((tmp_path / "summary.json").read_text())["overall"][0]["algorithm"] == "sb3_ppo"


def test_restore_counts_published_cells_as_finished_on_a_new_machine(tmp_path, trained):
    runs_dir, out = tmp_path / "runs", tmp_path / "out"
    shutil.copytree(trained, runs_dir / trained.name)
    publish(runs_dir, out, report=False)
    shutil.rmtree(runs_dir)  # a new machine: the published cells, no run folders
    run = Run("sb3_ppo", SCENARIO, 0, 64)
    assert status(run, runs_dir) == ("pending", 0)
    assert rl_at_scale.restore(out, runs_dir) == [trained.name]
    assert status(run, runs_dir) == ("done", 64)
    assert json.loads((runs_dir / trained.name / "result.json").read_text()) == \
        json.loads((trained / "result.json").read_text())
    assert rl_at_scale.restore(out, runs_dir) == []  # a folder with its result is left alone
    assert publish(runs_dir, out, report=False) == publish(runs_dir, out, report=False)


def test_success_differ_is_fishers_exact_test():
    pytest.importorskip("scipy")
    from benchmarks.rl_at_scale_report import success_differ

    assert success_differ(1.0, 0.0, 50) and success_differ(0.9, 0.6, 100)  # p = 1e-29, 1.2e-6
    assert not success_differ(0.5, 0.54, 50) and not success_differ(0.8, 0.9, 10)
    assert not success_differ(0.3, 0.5, 50)  # p = 0.066: a 20-point gap that 50 episodes cannot tell apart
    assert success_differ(0.3, 0.5, 50, alpha=0.1)
