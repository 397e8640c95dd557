"""Filtering generated tasks by the planner (planners/task_filter.py): ``impact-env filter``.

The fast suite plans one small task through the CLI; the slow suite plans 10 tasks per family and flies
every kept one with the expert.
"""

from __future__ import annotations

import json

import pytest

from impact_env.cli import main
from impact_env.errors import ImpactEnvError
from impact_env.transport.generate import FAMILIES, generate_toml
from planners import task_filter
from planners.errors import PlannerError
from planners.task_filter import FilterConfig, filter_task, load_kept, parse_seeds


def test_parse_seeds_and_config_errors():
    assert parse_seeds("3:6") == [3, 4, 5] and parse_seeds("7") == [7] and parse_seeds("1,4") == [1, 4]
    for bad in ("a:b", "5:5", "-1", ""):
        with pytest.raises(ImpactEnvError, match="--seeds"):
            parse_seeds(bad)
    with pytest.raises(PlannerError, match="node_limit"):
        FilterConfig(node_limit=0)
    with pytest.raises(PlannerError, match="min_robustness_m"):
        FilterConfig(min_robustness_m=-1.0)
    with pytest.raises(PlannerError, match="contact_cones"):
        FilterConfig(contact_cones=3)
    # the room rows are opt-in (docs/generated_tasks.md#room-for-the-disc-robot): point robots by default
    assert FilterConfig().planner_config().contact_cones is None
    assert FilterConfig(contact_cones=8).planner_config().contact_cones == 8


def test_cli_filter_keeps_a_planned_task_with_its_plan_and_resumes(tmp_path, capsys, monkeypatch):
    out = tmp_path / "kept"
    assert main(["filter", "--family", "throw_and_catch", "--seeds", "0", "--out", str(out)]) == 0
    assert "kept 1 of 1 throw_and_catch tasks" in capsys.readouterr().out
    (verdict,) = [json.loads(line) for line in (out / "verdicts.jsonl").read_text().splitlines()]
    assert verdict["kept"] and verdict["reason"] == "planned" and verdict["robustness_m"] > 1e-3
    assert (out / "throw_and_catch_0.toml").read_text() == generate_toml("throw_and_catch", 0)
    ((scenario, plan, cell),) = load_kept(out)
    assert plan.scenario == scenario.name == "throw_and_catch_0" and plan.robustness == verdict["robustness_m"]
    assert plan.fingerprint() == verdict["plan_fingerprint"]

    def no_planning(*args, **kwargs):
        raise AssertionError("a task already in verdicts.jsonl was planned again")

    monkeypatch.setattr(task_filter, "plan_spatially_robust", no_planning)
    assert main(["filter", "--family", "throw_and_catch", "--seeds", "0", "--out", str(out)]) == 0


def test_a_plan_below_the_robustness_floor_drops_the_task_with_its_reason():
    verdict, plan = filter_task("throw_and_catch", 0, FilterConfig(min_robustness_m=10.0))
    assert plan is None and not verdict.kept and verdict.reason == "low_robustness"
    assert verdict.robustness_m is not None and verdict.robustness_m < 10.0


def test_load_kept_needs_a_filtered_folder(tmp_path):
    with pytest.raises(ImpactEnvError, match="no verdicts.jsonl"):
        load_kept(tmp_path)


@pytest.mark.slow
@pytest.mark.parametrize("family", FAMILIES)
def test_ten_tasks_per_family_planned_and_every_kept_one_flown_by_the_expert(family, tmp_path):
    from benchmarks.task_generator import fly

    verdicts = task_filter.filter_tasks(family, range(10), tmp_path, progress=False)
    kept = load_kept(tmp_path)
    assert len(kept) == sum(v.kept for v in verdicts) >= 1
    for scenario, plan, cell in kept:
        assert plan.robustness > 1e-3 and cell["budget"] == "nodes"
        plan.check(scenario, tol=1e-5)
        flight = fly(scenario, plan)
        assert flight["steps"] == round(scenario.tf_s / scenario.control_period_s)
    # the node budget on one thread: the same verdict and plan again
    again, plan = filter_task(family, kept[0][2]["seed"])
    assert again.plan_fingerprint == kept[0][2]["plan_fingerprint"]
