"""``benchmarks.planner_speed``: one planner call per row, with this checkout's options (the satisfaction margin)
reaching the planner, and its arguments checked."""

from __future__ import annotations

import sys

import pytest

from benchmarks import planner_speed
from planners.errors import InfeasiblePlanError
from tests.paths import ROOT

SCENARIO = str(ROOT / "impact_env" / "transport" / "scenarios" / "throw_and_catch_exp.toml")


def test_a_call_reports_the_plan_it_made(shipped_plans):
    row = planner_speed.plan_call(SCENARIO, None, None, "sr", None, 0.0)
    assert row["ended"] == "optimal" and row["gap"] <= 1e-4
    assert row["rho"] == pytest.approx(0.4, abs=1e-6) and row["objective"] == row["rho"]
    assert row["fingerprint"] == shipped_plans.sr("throw_and_catch_exp").fingerprint()
    assert row["wall_s"] > 0 and row["cpu_s"] > 0 and row["stage1_nodes"] >= 1


def test_the_margin_reaches_the_planner():
    """A margin above the scenario's best rho (0.4 m) leaves no plan: the call raises, as the planner does."""
    with pytest.raises(InfeasiblePlanError):
        planner_speed.plan_call(SCENARIO, None, None, "sr", None, 0.45)


@pytest.mark.parametrize("margins", ["x", "0.1,-1", "2"])
def test_bad_margins_are_refused(monkeypatch, capsys, margins):
    monkeypatch.setattr(sys, "argv", ["planner_speed", "--margins", margins, "--ref", "",
                                      "--scenarios", "throw_and_catch_exp"])
    with pytest.raises(SystemExit) as info:
        planner_speed.main()
    assert info.value.code == 2 and "--margins" in capsys.readouterr().err
