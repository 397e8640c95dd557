"""Both MILP planners end through ``planners.offline.stages.solve_to_plan``: the plan read back from the stages'
answer carries their statistics and gap, and a time limit that cut stage 1 after it found a plan raises
PlanTimeoutError with that plan and the planner's own best value in the message."""

from __future__ import annotations

import dataclasses

import pytest

from impact_env.transport.scenario import load_scenario
from planners.errors import PlanTimeoutError
from planners.offline import stages
from planners.offline.impact_robust import plan_impact_robust
from planners.offline.solvers.base import Status
from planners.offline.spatially_robust import plan_spatially_robust

PLANNERS = {
    "sr": (plan_spatially_robust, lambda plan: f"best robustness {plan.robustness:.4f} m"),
    "ir": (plan_impact_robust, lambda plan: f"best delta {plan.delta_mps:.5f} m/s"),
}


@pytest.mark.parametrize("name", sorted(PLANNERS))
def test_a_time_limit_after_a_plan_raises_with_the_plan_the_stages_found(monkeypatch, name):
    """The stages run for real; only their stage-1 status is turned into a time limit (gap 0.25), so the plan
    in the error must be the very plan the planner returns without the cut, checked, with the stages' stats."""
    planner, best = PLANNERS[name]
    scenario = load_scenario("throw_and_catch_exp")
    plain = planner(scenario)
    real = stages.solve_stages

    def cut_by_the_time_limit(*args, **kwargs):
        solution = real(*args, **kwargs)
        solution.result = dataclasses.replace(solution.result, status=Status.TIME_LIMIT, mip_gap=0.25)
        return solution

    monkeypatch.setattr(stages, "solve_stages", cut_by_the_time_limit)
    with pytest.raises(PlanTimeoutError) as info:
        planner(scenario)
    plan = info.value.plan
    assert plan.planner == name and plan.fingerprint() == plain.fingerprint()
    assert info.value.mip_gap == 0.25 and plan.mip_gap == 0.25
    assert str(info.value) == f"time limit of 60.0 s reached with gap 0.25; {best(plan)}"
    assert plan.stats["refine_status"] == plain.stats["refine_status"] != "skipped"
    assert "polish_s" in plan.stats
