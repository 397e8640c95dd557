"""A task no trajectory satisfies, though a MILP held at r >= 0 reaches r = -1e-7 within its tolerances, is
reported infeasible, naming the conflicting conjuncts, by both offline planners and by ``impact-env plan``
(issue 24: ``F[0,100] in(O1,goal) & G[0,100] !in(O1,goal)`` ran to the time limit and wrote a plan with
robustness -1e-7)."""

from __future__ import annotations

import pytest

from impact_env.transport.scenario import scenario_from_dict
from planners.errors import InfeasiblePlanError, PlannerError
from planners.offline.config import IRPlannerConfig, PlannerConfig, SolverOptions
from planners.offline.impact_robust import plan_impact_robust
from planners.offline.spatially_robust import plan_spatially_robust
from tests.fuzz.strategies import DICTS, TEXTS
from tests.helpers import one_line_error

UNSATISFIABLE = "F[0,100] in(O1, goal) & G[0,100] !in(O1, goal)"
CONJUNCTS = ["task: F[0, 100] in(O1, goal)", "task: G[0, 100] !in(O1, goal)"]
# a generous budget: the infeasibility proof takes seconds, and the test must not pass by hitting a limit
BUDGET = SolverOptions(time_limit_s=300.0)


def unsatisfiable():
    return scenario_from_dict(DICTS["corridor"] | {"name": "unsatisfiable", "task": UNSATISFIABLE})


def test_the_spatially_robust_planner_reports_infeasible():
    with pytest.raises(InfeasiblePlanError) as info:
        plan_spatially_robust(unsatisfiable(), PlannerConfig(solver_options=BUDGET))
    assert str(info.value).startswith("infeasible:")
    assert sorted(info.value.groups) == CONJUNCTS


def test_the_impact_robust_planner_reports_infeasible():
    with pytest.raises(InfeasiblePlanError) as info:
        plan_impact_robust(unsatisfiable(), IRPlannerConfig(solver_options=BUDGET))
    assert sorted(info.value.groups) == CONJUNCTS


def test_plan_command_reports_infeasible_and_writes_nothing(tmp_path, capsys):
    scenario = tmp_path / "unsatisfiable.toml"
    text = TEXTS["corridor"]
    start = text.index('task = """')
    end = text.index('"""', start + 10) + 3
    scenario.write_text(text[:start] + f'task = "{UNSATISFIABLE}"' + text[end:])
    out = tmp_path / "plan.json"
    err = one_line_error(["plan", str(scenario), "--time-limit", "300", "--json", str(out), "--quiet"], capsys)
    assert "infeasible: no plan satisfies the task" in err and all(c in err for c in CONJUNCTS)
    assert not out.exists()


def test_a_satisfiable_task_keeps_its_robustness():
    plan = plan_spatially_robust(scenario_from_dict(DICTS["throw_and_catch_exp"]))
    assert plan.robustness == pytest.approx(0.4, abs=1e-6)


@pytest.mark.parametrize("value", [-1e-3, 2.0, float("nan"), "0"])
def test_min_robustness_is_checked(value):
    with pytest.raises(PlannerError, match="min_robustness_m"):
        PlannerConfig(min_robustness_m=value)


def test_the_online_replanner_keeps_the_old_constraint():
    """In flight a remainder at rho = 0 is still the best continuation: the mission replans with margin 0, so its
    remainders are the plans 0.2 made."""
    import inspect

    import planners.online.mission as mission

    source = inspect.getsource(mission.MissionPlanner._solve)  # every re-plan's config (IR re-plans take it too)
    assert "min_robustness_m=0.0" in source and "dataclasses.replace(self.planner_config" in source
