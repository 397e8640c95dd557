"""Tampered plan files (issue 11): ``Plan.from_dict`` / ``Plan.check`` name the field of every problem, and
``impact-env run --plan`` reports it in one line instead of a traceback."""

from __future__ import annotations

import copy
import json
import math

import pytest

from impact_env.cli import main
from impact_env.transport.scenario import load_scenario
from planners.errors import PlanCheckError
from planners.plan import Plan
from tests.paths import DATA

PLAN_FILE = DATA / "plans" / "bench" / "corridor.json"  # results/baselines/plans/
PLAN = json.loads(PLAN_FILE.read_text())
CORRIDOR = load_scenario("corridor")


def tampered(edit) -> dict:
    data = copy.deepcopy(PLAN)
    edit(data)
    return data


def nested(depth: int) -> list:
    root = node = []
    for _ in range(depth):
        node.append([])
        node = node[0]
    return root


def set_point(d, value):
    d["bodies"]["R1"]["segments"][2]["control_points"][1][0] = value


CASES = [
    ("NaN control point", lambda d: set_point(d, math.nan), r"bodies\.R1\.segments\[2\]\.control_points\[1\]\[0\] must "
                                                             r"be a finite number"),
    ("bodies is a list", lambda d: d.__setitem__("bodies", []), r"bodies must be a non-empty object"),
    ("unknown robot", lambda d: d["impacts"][0].__setitem__("robot", "R9"), r"impacts\[0\]: robot 'R9' is not a robot"),
    ("object as robot", lambda d: d["impacts"][0].__setitem__("robot", "O1"), r"impacts\[0\]: robot 'O1' is not"),
    ("empty segments", lambda d: d["bodies"]["O1"].__setitem__("segments", []),
     r"bodies\.O1\.segments must not be empty"),
    ("3 coordinates", lambda d: d["bodies"]["R2"]["segments"][0].__setitem__("control_points", [[1, 2, 3]] * 5),
     r"control_points\[0\] must be a list of 2 numbers"),
    ("one point", lambda d: d["bodies"]["R2"]["segments"][0].__setitem__("control_points", [[1, 9]]),
     r"control_points must be a list of 2 to 9 points"),
    ("huge time", lambda d: d["impacts"][1].__setitem__("time_s", 1e300), r"impacts\[1\]\.time_s must be a finite"),
    ("huge segment time", lambda d: d["bodies"]["R1"]["segments"][-1].__setitem__("t1_s", 1e300), r"t1_s must be"),
    ("deep nesting", lambda d: d.__setitem__("stats", {"log": nested(100_000)}), r"stats is nested more than 8 levels"),
    ("duplicated impact", lambda d: d["impacts"].append(copy.deepcopy(d["impacts"][0])), r"is listed twice"),
    ("kind 42", lambda d: d["bodies"]["R1"].__setitem__("kind", 42), r"bodies\.R1\.kind must be one of 'robot', "
                                                                     r"'object', got 42"),
    ("3-D impact position", lambda d: d["impacts"][0].__setitem__("position", [1.0, 2.0, 0.0]),
     r"impacts\[0\]\.position must be a list of 2 numbers"),
    ("swapped kind", lambda d: d["bodies"]["O1"].__setitem__("kind", "robot"), r"O1: kind 'robot' in the plan, but"),
    ("unknown field", lambda d: d["impacts"][0].__setitem__("impulse", 3), r"impacts\[0\]\.impulse: unknown field"),
    ("missing field", lambda d: d["bodies"]["R1"]["segments"][0].pop("t0_s"), r"segments\[0\]\.t0_s is required"),
    ("extra body", lambda d: d["bodies"].__setitem__("X1", copy.deepcopy(d["bodies"]["O1"])), r"X1: in the plan but"),
    ("missing body", lambda d: d["bodies"].pop("R2"), r"R2: missing from the plan"),
    ("string robustness", lambda d: d.__setitem__("robustness", "0.75"), r"robustness must be a number"),
    ("time copy differs", lambda d: d["impacts"][0].__setitem__("time", 3.0), r"impacts\[0\]\.time = 3\.0 differs"),
]


def test_the_committed_plan_passes():
    Plan.from_dict(copy.deepcopy(PLAN)).check(CORRIDOR, tol=1e-5)


@pytest.mark.parametrize("label, edit, message", CASES, ids=[c[0] for c in CASES])
def test_tampered_plan_is_a_plan_check_error_naming_the_field(label, edit, message):
    with pytest.raises(PlanCheckError, match=message):
        Plan.from_dict(tampered(edit)).check(CORRIDOR, tol=1e-5)


def test_every_problem_is_listed():
    data = tampered(lambda d: (set_point(d, math.inf), d["impacts"][0].__setitem__("position", [1])))
    with pytest.raises(PlanCheckError) as info:
        Plan.from_dict(data)
    assert len(info.value.violations) == 2


@pytest.mark.parametrize("text, message", [
    ("[" * 100_000, "nested too deeply"),
    ("{\"scenario\": ", "not a JSON plan file"),
    ("[1, 2]", "the plan must be a JSON object, got list"),
])
def test_broken_plan_files(tmp_path, text, message):
    path = tmp_path / "plan.json"
    path.write_text(text)
    with pytest.raises(PlanCheckError, match=message):
        Plan.load(path)


def test_non_utf8_plan_file(tmp_path):
    path = tmp_path / "plan.json"
    path.write_bytes(b"\xff\xfe{}")
    with pytest.raises(PlanCheckError, match="not a JSON plan file"):
        Plan.load(path)


def test_programmatic_plan_with_nan_fails_the_check():
    plan = Plan.from_dict(copy.deepcopy(PLAN))
    plan.bodies["R1"].segments[3].control_points[2, 1] = math.nan
    with pytest.raises(PlanCheckError, match="R1: segment 3 has non-finite control points"):
        plan.check(CORRIDOR, tol=1e-5)


@pytest.mark.parametrize("label, edit, message", CASES[:6], ids=[c[0] for c in CASES[:6]])
def test_run_with_a_tampered_plan_is_one_line_exit_2(tmp_path, capsys, label, edit, message):
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(tampered(edit)))
    assert main(["run", "corridor", "--controller", "expert", "--plan", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("impact-env: error: plan check failed") and "Traceback" not in err
