"""The statistics and tables of benchmarks/task_generator.py and benchmarks/task_bc.py, on cells of known values."""

from __future__ import annotations

import json
import math

import pytest

from benchmarks import task_bc, task_generator
from benchmarks.task_bc import bootstrap_ci
from benchmarks.task_generator import wilson


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
