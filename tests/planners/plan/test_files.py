"""Plan files (planners/plan/files.py): both plan types are written and read back the same way, and a file that
cannot be read or parsed is the plan type's own typed error naming the file, never a raw traceback."""

from __future__ import annotations

import json
import re

import pytest

from planners.errors import PlanCheckError, PlannerError
from planners.plan import Plan
from planners.plan.files import read_plan_json, write_plan_json
from planners.tether.plan import FORMAT, Pull, TetherPlan, is_tether_plan_file

BROKEN = [  # file bytes, what the message says
    (b"[" * 100_000, "is nested too deeply to be a"),
    (b"{\"format\": ", "is not a JSON"),
    (b"\xff\xfe{}", "is not a JSON"),
]


def tether_plan() -> TetherPlan:
    pulls = [Pull(0, (1.0, 1.0), (2.0, 1.0)), Pull(1, (2.0, 1.0), (2.0, 3.5))]
    return TetherPlan("L", (1.0, 1.0), (1.5, 2.5, 3.0, 4.0), pulls, pull_speed_mps=0.1, switch_time_s=5.0,
                      method="test", stats={"nodes": 3})


def test_a_tether_plan_comes_back_as_saved(tmp_path):
    plan = tether_plan()
    path = plan.save(tmp_path / "deep" / "plan.json")
    assert json.loads(path.read_text())["format"] == FORMAT and is_tether_plan_file(path)
    back = TetherPlan.load(path)
    assert back.pulls == plan.pulls and back.goal_box == plan.goal_box and back.stats == plan.stats
    assert back.travel_time_s(2) == pytest.approx((1.0 + 2.5) / 0.1 + 5.0)


def test_write_plan_json_makes_the_folders_and_keeps_the_indent(tmp_path):
    path = write_plan_json(tmp_path / "a" / "b.json", {"x": [1, 2]}, indent=1)
    assert path.read_text() == json.dumps({"x": [1, 2]}, indent=1)
    assert read_plan_json(path, PlannerError) == {"x": [1, 2]}


@pytest.mark.parametrize("raw, message", BROKEN, ids=["deep", "truncated", "not-utf8"])
def test_broken_files_are_each_plan_types_own_error(tmp_path, raw, message):
    path = tmp_path / "plan.json"
    path.write_bytes(raw)
    with pytest.raises(PlannerError, match=f"^tether plan {re.escape(str(path))} {message} ") as info:
        TetherPlan.load(path)
    assert type(info.value) is PlannerError
    with pytest.raises(PlanCheckError) as info:
        Plan.load(path)
    assert len(info.value.violations) == 1 and re.match(f"plan {re.escape(str(path))} {message} ",
                                                          info.value.violations[0])
    assert not is_tether_plan_file(path)


def test_a_missing_file_or_a_folder_cannot_be_read(tmp_path):
    for path in (tmp_path / "nope.json", tmp_path):
        with pytest.raises(PlannerError, match=f"^cannot read tether plan {re.escape(str(path))}: "):
            TetherPlan.load(path)
        with pytest.raises(PlanCheckError) as info:
            Plan.load(path)
        assert re.fullmatch(f"cannot read plan {re.escape(str(path))}: .+", info.value.violations[0])
        assert not is_tether_plan_file(path)


def test_json_that_is_not_a_tether_plan(tmp_path):
    path = tmp_path / "plan.json"
    for text, message, has_format in (("[1, 2]", "not a tether plan: a JSON list", False),
                                      ('{"format": "x/0"}', "not a tether plan: format is 'x/0'", False),
                                      (json.dumps({"format": FORMAT}), "malformed tether plan:\n  station is", True)):
        path.write_text(text)
        with pytest.raises(PlannerError, match=message):
            TetherPlan.load(path)
        assert is_tether_plan_file(path) == has_format  # the dispatch test reads the format only
