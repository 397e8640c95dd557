"""``PlannerConfig.conjunct_weight``: each top-level conjunct's own robustness joins the maximised rho with a
small weight, so that a conjunct that does not set rho keeps the margin it can have instead of any margin down
to rho (issue 22: a mission re-plan left the object that did not set rho at rho from its goal's edge, and the
noise of its last impact carried it out). On ``tests/data/own_margins.toml`` O1's goal caps rho at 0.2 m; O2
must be pushed into a wide goal, where it could keep 0.8 m. The mission's re-plans take the weight from
``MissionConfig.conjunct_weight`` (``tests/planners/online/test_mission_finer_grid.py``)."""

from __future__ import annotations

import numpy as np
import pytest

from impact_env.stl import robustness
from impact_env.transport.scenario import load_scenario
from planners.errors import PlannerError
from planners.offline.config import PlannerConfig
from planners.offline.spatially_robust import plan_spatially_robust
from planners.online.mission import MissionConfig
from tests.paths import DATA


def conjunct_margins(weight: float) -> tuple[float, list[float]]:
    """rho of the plan, and each conjunct's robustness on the plan's trajectory sampled at the control period."""
    scenario = load_scenario(DATA / "own_margins.toml")
    plan = plan_spatially_robust(scenario, PlannerConfig(conjunct_weight=weight))
    plan.check(scenario)
    times = np.arange(0.0, scenario.tf_s + 1e-9, scenario.control_period_s)
    trace = {name: plan.position(name, times) for name in plan.bodies}
    return plan.robustness, [robustness(c, trace, scenario.region_map(), dt=scenario.control_period_s)
                             for c in scenario.formula.children]


def test_without_the_weight_the_conjunct_that_does_not_set_rho_is_left_near_rho():
    rho, (r1, r2) = conjunct_margins(0.0)
    assert rho == pytest.approx(0.2, abs=1e-6) and r1 == pytest.approx(0.2, abs=1e-6)
    assert r2 < 0.4  # the cheapest push that keeps O2 0.2 m inside B: nothing asks for more


def test_with_the_weight_it_keeps_its_own_margin_and_rho_is_unchanged():
    rho, (r1, r2) = conjunct_margins(0.3)
    assert rho == pytest.approx(0.2, abs=1e-6) and r1 == pytest.approx(0.2, abs=1e-6)
    assert r2 > 0.7  # O2 sent deep into B (B's half-height is 1 m; the window is 5 s of O2 moving)


@pytest.mark.parametrize("weight", [-0.1, 1.5, float("nan")])
def test_a_weight_outside_0_to_1_is_refused(weight):
    with pytest.raises(PlannerError, match="conjunct_weight"):
        PlannerConfig(conjunct_weight=weight)
    with pytest.raises(PlannerError, match="conjunct_weight"):
        MissionConfig(conjunct_weight=weight)
