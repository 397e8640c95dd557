"""Tampered plan files of every kind give typed errors naming the field and the file (issue 24: a plan whose
``stats`` is a string gave an ``AttributeError`` traceback in ``impact-env run``)."""

from __future__ import annotations

import copy
import json

import pytest

from planners.errors import PlanCheckError, PlannerError
from planners.plan import Plan
from planners.tether.plan import TetherPlan
from tests.helpers import one_line_error
from tests.paths import DATA

PLANS = DATA / "plans"
SR_PLAN = json.loads((PLANS / "bench" / "corridor.json").read_text())
IR_PLAN = json.loads((PLANS / "ir" / "corridor.json").read_text())


@pytest.fixture(scope="module")
def tether_plan() -> dict:
    from impact_env.tether.station import load_station
    from planners.tether.reachability import plan_reachability

    return plan_reachability(load_station("L")).to_dict()


@pytest.mark.parametrize("stats, message", [
    ("x", "stats must be a JSON object of the planner's numbers, got 'x'"),
    ([1, 2], "stats must be a JSON object"),
    (3.5, "stats must be a JSON object"),
    ({"intervals": "ten"}, "stats.intervals must be an integer in 1..100000, got 'ten'"),
    ({"intervals": 1.5}, "stats.intervals must be an integer"),
    ({"robot_degree": 99}, "stats.robot_degree must be an integer in 1..8"),
    ({"refine_status": 7}, "stats.refine_status must be a string"),
    ({"refine_s": -1}, "stats.refine_s must be a finite number"),
    ({"refine_objective": "big"}, "stats.refine_objective must be a number"),
])
@pytest.mark.parametrize("original", [SR_PLAN, IR_PLAN], ids=["sr", "ir"])
def test_tampered_stats_are_plan_check_errors(stats, message, original, tmp_path):
    data = copy.deepcopy(original)
    data["stats"] = stats
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(data))
    with pytest.raises(PlanCheckError) as info:
        Plan.load(path)
    assert message in str(info.value) and str(path) in str(info.value)


def test_tampered_stats_in_run_is_one_line(tmp_path, capsys):
    data = copy.deepcopy(SR_PLAN)
    data["stats"] = "x"
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(data))
    err = one_line_error(["run", "corridor", "--controller", "expert", "--plan", str(path)], capsys)
    assert "stats must be a JSON object" in err and str(path) in err


def test_free_stats_still_load(tmp_path):
    data = copy.deepcopy(SR_PLAN)
    data["stats"] = {**data["stats"], "note": "hand edited", "intervals": None, "extra": [1, {"a": None}]}
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(data))
    assert Plan.load(path).stats["note"] == "hand edited"


def _set(data: dict, path: str, value) -> dict:
    out = copy.deepcopy(data)
    keys = [int(k) if k.lstrip("-").isdigit() else k for k in path.split(".")]
    node = out
    for k in keys[:-1]:
        node = node[k]
    if value is KeyError:
        del node[keys[-1]]
    else:
        node[keys[-1]] = value
    return out


@pytest.mark.parametrize("field, value, message", [
    ("stats", "x", "stats must be a JSON object"),
    ("stats.targets", "x", "stats.targets must be a list of 3 integers"),
    ("stats.targets", [1, 2], "stats.targets must be a list of 3 integers"),
    ("pull_speed_mps", 0, "pull_speed_mps must be > 0"),
    ("pull_speed_mps", "fast", "pull_speed_mps must be a number"),
    ("switch_time_s", -1.0, "switch_time_s must be a finite number"),
    ("start_m", [1.0], "start_m must be a list of 2 numbers"),
    ("start_m", [1e300, 0.0], "start_m[0] must be a finite number"),
    ("goal_box", [1, 0, 0, 1], "goal_box = [1.0, 0.0, 0.0, 1.0] must have xmin <= xmax"),
    ("goal_box", "box", "goal_box must be [xmin, xmax, ymin, ymax]"),
    ("pulls", {"a": 1}, "pulls must be a list"),
    ("pulls.0.anchor", 1.5, "pulls[0].anchor must be an anchor index"),
    ("pulls.0.anchor", -1, "pulls[0].anchor must be an anchor index"),
    ("pulls.0.anchor", True, "pulls[0].anchor must be an anchor index"),
    ("pulls.0.end_m", None, "pulls[0].end_m must be a list of 2 numbers"),
    ("pulls.0.extra", 1, "pulls[0].extra: unknown field"),
    ("station", KeyError, "station is required"),
    ("method", 3, "method must be a string"),
    ("solve_time_s", float("nan"), "solve_time_s must be a finite number"),
])
def test_tampered_tether_plans_are_planner_errors(tether_plan, field, value, message, tmp_path):
    path = tmp_path / "tether_plan.json"
    path.write_text(json.dumps(_set(tether_plan, field, value)))
    with pytest.raises(PlannerError) as info:
        TetherPlan.load(path)
    assert message in str(info.value)


def test_a_tether_plan_round_trips(tether_plan, tmp_path):
    plan = TetherPlan.from_dict(tether_plan)
    again = TetherPlan.load(plan.save(tmp_path / "p.json"))
    assert again.to_dict() == plan.to_dict()


def test_tampered_tether_plan_in_run_is_one_line(tether_plan, tmp_path, capsys):
    path = tmp_path / "tether_plan.json"
    path.write_text(json.dumps(_set(tether_plan, "stats", "x")))
    err = one_line_error(["run", "L", "--controller", "expert", "--plan", str(path)], capsys)
    assert "malformed tether plan" in err and "stats must be a JSON object" in err
