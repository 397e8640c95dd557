"""``impact-env plan``: the plan JSON and PNG it writes, its output, its exit codes and error messages."""

from __future__ import annotations

import contextlib
import importlib.util
import io
import json
import re
import sys
from importlib.resources import files

import pytest

from impact_env.cli import main
from impact_env.transport.scenario import load_scenario
from planners.errors import PlanTimeoutError
from planners.offline.solvers.base import Progress
from planners.plan import Plan

SCENARIO = "throw_and_catch_exp"
IMPACT_KEYS = {"time", "robot", "object", "position", "object_velocity_before", "object_velocity_after",
               "robot_velocity_before", "robot_velocity_after"}


@pytest.fixture(scope="module")
def planned(tmp_path_factory):
    """Run ``impact-env plan throw_and_catch_exp --out X --plot Y`` once; (exit code, stdout, X, Y)."""
    folder = tmp_path_factory.mktemp("plan")
    out, png = folder / "plan.json", folder / "plan.png"
    stdout = io.StringIO()
    with contextlib.redirect_stdout(stdout):
        code = main(["plan", SCENARIO, "--out", str(out), "--plot", str(png)])
    return code, stdout.getvalue(), out, png


def test_plan_writes_a_checked_plan_json_and_a_png(planned):
    code, _, out, png = planned
    assert code == 0
    data = json.loads(out.read_text())
    required = {"scenario", "planner", "robustness", "solve_time_s", "mip_gap", "solver", "impacts", "bodies"}
    assert required <= set(data)
    assert data["scenario"] == SCENARIO and data["planner"] == "sr" and data["solver"] == "highs"
    assert data["robustness"] >= 0.0 and data["impacts"]
    for impact in data["impacts"]:
        assert IMPACT_KEYS <= set(impact)
    assert set(data["bodies"]) == {"R1", "R2", "O1"}
    for body in data["bodies"].values():
        assert body["segments"] and all(len(s["control_points"]) >= 2 for s in body["segments"])
    scenario = load_scenario(SCENARIO)
    Plan.load(out).check(scenario)  # raises PlanCheckError listing violations
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000


def test_plan_prints_model_size_result_and_one_line_per_impact(planned):
    _, stdout, out, _ = planned
    plan = Plan.load(out)
    assert re.search(rf"{plan.stats['binaries']} binaries, \d+ variables, {plan.stats['rows']} rows", stdout)
    assert f"robustness rho = {plan.robustness:.4f} m" in stdout
    impact_lines = [line for line in stdout.splitlines() if re.match(r"\s+I\d+\s+t =", line)]
    assert len(impact_lines) == len(plan.impacts)
    first = plan.impacts[0]
    assert f"{first.robot} -> {first.object}" in impact_lines[0] and f"t = {first.time_s:6.2f} s" in impact_lines[0]
    assert f"stage 2 (fewest impacts, least acceleration, rho kept): {plan.stats['refine_status']}" in stdout


def test_plot_plan_returns_a_figure_with_three_axes(planned, tmp_path):
    from matplotlib.figure import Figure

    from planners.plan.plotting import plot_plan

    _, _, out, _ = planned
    plan = Plan.load(out)
    fig = plot_plan(load_scenario(SCENARIO), plan, samples=50)
    assert isinstance(fig, Figure) and len(fig.axes) == 3
    xy, positions, velocities = fig.axes
    assert positions.get_shared_x_axes().joined(positions, velocities)
    # one red star per impact in the xy view, one dotted line per impact in each time panel
    stars = [c for c in xy.collections if c.get_label() == "impact"]
    assert len(stars) == 1 and len(stars[0].get_offsets()) == len(plan.impacts)
    for ax in (positions, velocities):
        dotted = [ln for ln in ax.get_lines() if ln.get_linestyle() == ":"]
        assert sorted(ln.get_xdata()[0] for ln in dotted) == pytest.approx([i.time_s for i in plan.impacts])
    # velocity lines break (NaN) at impacts instead of drawing a slanted line across the jump
    assert any(any(v != v for v in ln.get_ydata()) for ln in velocities.get_lines())
    path = tmp_path / "nosuffix"
    plot_plan(load_scenario(SCENARIO), plan, path, samples=50)
    assert (tmp_path / "nosuffix.png").stat().st_size > 0


def test_time_limit_with_a_plan_keeps_it_and_exits_3(planned, tmp_path, monkeypatch, capsys):
    _, _, out, _ = planned
    best = Plan.load(out)

    def times_out(scenario, config):
        raise PlanTimeoutError("time limit reached", plan=best, mip_gap=0.25)

    monkeypatch.setattr("planners.offline.spatially_robust.plan_spatially_robust", times_out)
    again = tmp_path / "best.json"
    assert main(["plan", SCENARIO, "--time-limit", "1", "--quiet", "--out", str(again)]) == 3
    err = capsys.readouterr().err
    assert "warning" in err and "25.00%" in err
    assert json.loads(again.read_text())["robustness"] == best.robustness


def test_a_node_budget_reached_keeps_the_plan_warns_and_exits_3(tmp_path, capsys):
    out = tmp_path / "cut.json"
    assert main(["plan", "two_objects", "--node-limit", "1", "--refine-nodes", "0", "--quiet", "--json",
                 str(out)]) == 3
    err = capsys.readouterr().err
    assert "warning: node budget of 1 nodes reached with gap" in err and "keeping the best plan found" in err
    plan = Plan.load(out)
    assert plan.stats["stage1_status"] == "node_limit" and plan.mip_gap > 1e-4


def test_progress_lines_are_throttled_to_one_per_period(capsys):
    from planners.cli import format_progress, progress_printer  # matplotlib comes with it: not at collection

    now = [0.0]
    report = progress_printer(period_s=1.0, clock=lambda: now[0])
    for t in (0.0, 0.3, 0.9, 1.0, 1.5, 2.2):
        now[0] = t
        report(Progress(elapsed_s=t, incumbent=0.4123, bound=0.5, gap=0.175))
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 3  # at 0.0, 1.0 and 2.2
    assert lines[0] == "  t=   0.0 s  incumbent 0.4123  bound 0.5000  gap 17.5%"
    assert format_progress(Progress(3.1, None, None, None)).startswith("  t=   3.1 s  incumbent")


def _error(argv: list[str], capsys) -> str:
    assert main(argv) == 2
    return capsys.readouterr().err.strip()


def test_unknown_solver_is_a_one_line_error(capsys):
    err = _error(["plan", SCENARIO, "--solver", "cplex"], capsys)
    assert err.startswith("impact-env: error:") and "\n" not in err
    assert "unknown solver 'cplex'" in err and "highs" in err


def test_missing_gurobi_says_how_to_install_it(monkeypatch, capsys):
    if importlib.util.find_spec("gurobipy") is not None:
        monkeypatch.setitem(sys.modules, "gurobipy", None)  # installed here: make its import fail as if missing
    err = _error(["plan", SCENARIO, "--solver", "gurobi", "--quiet"], capsys)
    assert err.startswith("impact-env: error:") and "gurobi" in err.lower() and "install" in err


def test_infeasible_user_scenario_names_the_conflicting_groups(tmp_path, capsys):
    from planners.offline.spatially_robust import PlannerConfig, build_model

    text = files("impact_env.transport.scenarios").joinpath(f"{SCENARIO}.toml").read_text()
    text = text.replace("tf_s = 20.0", "tf_s = 2.0").replace("F[0,20]", "F[0,2]")
    assert "tf_s = 2.0" in text and "F[0,2]" in text
    path = tmp_path / "too_short.toml"
    path.write_text(text)
    err = _error(["plan", str(path), "--quiet"], capsys)
    assert err.startswith("impact-env: error:")
    groups = build_model(load_scenario(path), PlannerConfig()).model.groups()
    assert [g for g in groups if g in err], f"no constraint group named in: {err}"


def test_negative_refine_nodes_is_a_one_line_error(capsys):
    err = _error(["plan", SCENARIO, "--refine-nodes", "-1"], capsys)
    assert "--refine-nodes must be >= 0" in err and "\n" not in err
