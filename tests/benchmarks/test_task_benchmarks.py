"""The statistics and tables of benchmarks/task_generator.py and benchmarks/task_bc.py, on cells of known values."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from benchmarks import task_bc, task_generator
from benchmarks.task_bc import bootstrap_ci
from benchmarks.task_generator import wilson
from tests.optional import requires
from tests.paths import DATA


def test_wilson_interval_known_values():
    lo, hi = wilson(5, 10)
    assert lo == pytest.approx(0.2366, abs=1e-4) and hi == pytest.approx(0.7634, abs=1e-4)
    assert wilson(0, 10)[0] == 0.0 and wilson(10, 10)[1] == 1.0
    assert all(math.isnan(v) for v in wilson(0, 0))


def test_bootstrap_interval_is_degenerate_on_constant_outcomes_and_covers_the_mean():
    assert bootstrap_ci({"a": [1.0, 1.0], "b": [1.0]}) == (1.0, 1.0)
    lo, hi = bootstrap_ci({f"t{i}": [float(i % 2)] * 3 for i in range(20)})
    assert lo < 0.5 < hi


def _write(path, cells):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("".join(json.dumps(c) + "\n" for c in cells))


def test_generator_table_counts_kept_dropped_and_flown(tmp_path, monkeypatch):
    monkeypatch.setattr(task_generator, "OUT", tmp_path)
    verdict = {"family": "gaps", "budget": "nodes", "robustness_m": 0.2, "plan_s": 10.0}
    _write(tmp_path / "gaps" / "verdicts.jsonl", [
        {**verdict, "name": "gaps_0", "seed": 0, "kept": True, "reason": "planned"},
        {**verdict, "name": "gaps_1", "seed": 1, "kept": False, "reason": "infeasible", "robustness_m": None,
         "plan_s": 30.0},
        {**verdict, "name": "gaps_2", "seed": 2, "kept": True, "reason": "planned", "budget": "time"}])
    _write(tmp_path / "gaps" / "flights.jsonl", [
        {"name": "gaps_0", "success": True, "robustness_m": 0.3, "ms_per_step": 5.0},
        {"name": "gaps_2", "success": False, "robustness_m": -0.1, "ms_per_step": 7.0}])
    row = next(line for line in task_generator.table(["gaps"]).splitlines() if line.startswith("| gaps "))
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[1:6] == ["3", "2", "67 (21-94)", "infeasible: 1", "1"]
    assert cells[6] == "10.0 / 30.0" and cells[7].startswith("50 (") and cells[8] == "+0.100"


def task_bc_policy(run):
    from baselines.task_bc import TaskBCPolicy

    return TaskBCPolicy.load(run)


def test_bc_table_pools_training_seeds(tmp_path, monkeypatch):
    monkeypatch.setattr(task_bc, "OUT", tmp_path)
    episode = {"task": "gaps_0", "seed": 1000, "robustness_m": 0.1, "ms_per_step": 0.1}
    base = {"family": "gaps", "train_tasks": 3, "heldout_tasks": ["gaps_0"]}
    bc = {**base, "controller": "bc", "dataset_steps": 100, "epochs": 2, "final_loss": 0.1, "train_wall_s": 4.0}
    _write(tmp_path / "cells.jsonl", [
        {**base, "controller": "expert", "train_seed": None, "episodes": [{**episode, "success": True}] * 2},
        {**bc, "train_seed": 0, "episodes": [{**episode, "success": True}, {**episode, "success": False}]},
        {**bc, "train_seed": 1, "episodes": [{**episode, "success": False}] * 2}])
    rows = [line for line in task_bc.table().splitlines() if line.startswith("| gaps")]
    assert "| 100 (100-100) of 2 |" in rows[0] and "bc (2 seeds)" in rows[1] and "| 25 (" in rows[1]
    assert "| 50, 0 |" in rows[1]


def test_ratio_interval_is_paired_over_tasks():
    same = {f"t{i}": [float(i % 2)] * 4 for i in range(10)}
    assert task_bc.ratio_ci(same, same) == (1.0, 1.0, 1.0)  # a controller against itself, task by task
    half = {f"t{i}": [1.0, 0.0] for i in range(10)}
    ratio, lo, hi = task_bc.ratio_ci(half, {t: [1.0, 1.0] for t in half})
    assert ratio == 0.5 and lo < 0.5 < hi
    assert all(math.isnan(v) for v in task_bc.ratio_ci(half, {t: [0.0] for t in half}))


def test_bc_table_keeps_task_folders_and_labels_apart(tmp_path, monkeypatch):
    monkeypatch.setattr(task_bc, "OUT", tmp_path)
    win, lose = ({"task": "gaps_0", "seed": 1000, "success": s, "robustness_m": 0.1, "ms_per_step": 0.1}
                 for s in (True, False))
    bc = {"dataset_steps": 100, "epochs": 2, "final_loss": 0.1, "train_wall_s": 4.0}
    old = {"family": "gaps", "train_tasks": 3, "heldout_tasks": ["gaps_0"]}  # no tasks_dir: the default folder
    new = {**old, "tasks_dir": "snap", "train_tasks": 30}
    _write(tmp_path / "cells.jsonl", [
        {**old, "controller": "expert", "train_seed": None, "episodes": [win], "heldout_zero_action_mse": 0.05},
        {**old, **bc, "controller": "bc", "train_seed": 0, "episodes": [lose]},
        {**new, "controller": "expert", "train_seed": None, "episodes": [win, win]},
        {**new, **bc, "controller": "bc", "train_seed": 0, "episodes": [win, lose]},
        {**new, **bc, "controller": "bc_wide", "train_seed": 0, "episodes": [win, win], "train_mse": 0.01,
         "heldout_action_mse": 0.04}])
    rows = [line for line in task_bc.table().splitlines() if line.startswith("| gaps")]
    assert [r.split("|")[2].strip() for r in rows] == ["expert", "bc (1 seeds)", "expert", "bc (1 seeds)",
                                                        "bc_wide (1 seeds)"]
    assert "| zero action: 0.0500 |" in rows[0] and "| 3 / 1 |" in rows[1] and "| 0.00 (0.00-0.00) |" in rows[1]
    assert "| 30 / 1 |" in rows[3] and "| 0.50 (" in rows[3] and "| 1.00 (1.00-1.00) |" in rows[4]
    assert "| 0.0100 / 0.0400 |" in rows[4] and rows[3].count("| - |") == 1  # action MSE: only where measured


@requires("minari", "torch")
def test_bc_benchmark_runs_on_a_task_folder_and_never_trains_on_heldout_tasks(tmp_path, monkeypatch):
    """The whole benchmark at toy size on the two kept tasks of tests/data/generated (one per side)."""
    import shutil

    from impact_env.errors import ImpactEnvError

    for name, value in (("OUT", tmp_path / "out"), ("DATASETS", tmp_path / "ds"), ("RUNS", tmp_path / "runs")):
        monkeypatch.setattr(task_bc, name, value)
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(tmp_path / "ds"))
    shutil.copytree(DATA / "generated", tmp_path / "tasks" / "throw_and_catch")
    args = ["--families", "throw_and_catch", "--tasks", str(tmp_path / "tasks"), "--seeds", "0", "--epochs", "2",
            "--eval-episodes", "1", "--episodes-per-task", "1", "--heldout", "0.5", "--hidden", "16"]
    assert task_bc.main(args) == 0
    cells = [json.loads(line) for line in (tmp_path / "out" / "cells.jsonl").read_text().splitlines()]
    assert [(c["controller"], c["tasks_dir"]) for c in cells] == [("expert", str(tmp_path / "tasks")),
                                                                   ("bc", str(tmp_path / "tasks"))]
    held = cells[0]["heldout_tasks"]
    assert len(held) == 1 and all(e["task"] == held[0] for c in cells for e in c["episodes"])
    split = json.loads((tmp_path / "ds" / "throw_and_catch" / "impact_env" / "generated_throw_and_catch"
                        / "split.json").read_text())
    assert split["heldout"] == held and held[0] not in split["train"]
    assert cells[1]["dataset_episodes"] == 1 and cells[1]["settings"]["hidden"] == [16]
    # the held-out expert's steps, on which BC's action error is measured: those of its held-out episodes
    pairs = np.load(tmp_path / "ds" / "throw_and_catch" / "heldout_expert_pairs.npz")
    from impact_env.transport.generate import generate_task

    steps = round(generate_task("throw_and_catch", int(held[0].rsplit("_", 1)[1])).tf_s / 0.1)  # one episode's
    assert pairs["tasks"].tolist() == held and pairs["observations"].shape[0] == pairs["actions"].shape[0] == steps
    policy = task_bc_policy(tmp_path / "runs" / "throw_and_catch_bc_s0")
    assert cells[1]["heldout_action_mse"] == pytest.approx(
        np.mean([(policy.act(o) - a) ** 2 for o, a in zip(pairs["observations"], pairs["actions"])]), rel=1e-5)
    assert 0 < cells[1]["train_mse"] < 1 and 0 < cells[1]["heldout_action_mse"] < 4
    assert cells[0]["heldout_zero_action_mse"] == pytest.approx(float(np.mean(pairs["actions"] ** 2)))
    with pytest.raises(ImpactEnvError, match="another --label"):
        task_bc.main(args[:-1] + ["32"])  # other settings under a label already measured
    assert task_bc.main(args[:-2] + ["--hidden", "32", "--label", "bc_32"]) == 0
    rows = (tmp_path / "out" / "table.md").read_text().splitlines()
    assert [r.split("|")[2].strip() for r in rows[2:]] == ["expert", "bc (1 seeds)", "bc_32 (1 seeds)"]
