"""The scenarios shipped for issue 22's kinds of task (a narrow gap with a time window, one robot serving two
objects, a long sequence of timed visits ending at rest, robots starting within 5 cm of walls, four robots and
two objects): each loads, plans to a proven rho > 0 with every hand-over flyable, and its plan (the one the
robustness benchmark flies, results/robustness/plans/) delivers nominally with the full expert."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from impact_env.transport.scenario import load_scenario
from planners.offline.config import HandoverConfig, PlannerConfig, SolverOptions
from planners.offline.spatially_robust import plan_spatially_robust
from planners.plan import Plan
from planners.plan.handover import unflyable_handovers

PLANS = Path(__file__).resolve().parents[1] / "results" / "robustness" / "plans"
# name -> (the planned rho in m, impacts); the two heaviest models are planned in the slow run only
NEW = {"narrow_gap": (0.15, 4), "one_robot_two_objects": (0.4, 2), "wall_start": (0.4, 2),
       "timed_visits": (0.1564, 8), "four_robots": (0.5, 5)}
SLOW = {"timed_visits", "four_robots"}


def test_each_loads_with_what_it_is_for():
    gap = load_scenario("narrow_gap")
    upper, lower = (gap.region_map()[n].bounds for n in ("upper", "lower"))
    assert upper[2] - lower[3] == pytest.approx(0.7)  # the gap, 0.3 m wider than the object
    assert len(load_scenario("one_robot_two_objects").robots) == 1
    assert len(load_scenario("one_robot_two_objects").objects) == 2
    visits = load_scenario("timed_visits")
    assert str(visits.formula).count("in(O1") == 4 and visits.body("O1").final_velocity_mps == (0.0, 0.0)
    walls = load_scenario("wall_start")
    xmin, xmax, ymin, ymax = walls.world_box
    for r in walls.robots:
        x, y = r.position_m
        assert min(x - xmin, xmax - x, y - ymin, ymax - y) - r.radius_m <= 0.05  # within 5 cm of a wall
    four = load_scenario("four_robots")
    assert (len(four.robots), len(four.objects)) == (4, 2)


@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.slow) if n in SLOW else n for n in NEW])
def test_each_plans_to_a_proven_positive_robustness(name):
    scenario = load_scenario(name)
    # a generous safety net: the planner's node-cut stages decide the plan, not the clock
    plan = plan_spatially_robust(scenario, PlannerConfig(solver_options=SolverOptions(time_limit_s=600)))
    rho, impacts = NEW[name]
    assert plan.robustness == pytest.approx(rho, abs=1e-3) and rho > 0 and plan.mip_gap < 1e-3
    assert len(plan.impacts) == impacts
    assert unflyable_handovers(plan, scenario, HandoverConfig().margin) == []
    cached = Plan.from_dict(json.loads((PLANS / f"{name}.json").read_text()))
    assert cached.robustness == pytest.approx(plan.robustness, abs=1e-6)


@pytest.mark.slow
@pytest.mark.parametrize("name", list(NEW))
def test_each_plan_flies_nominally_with_the_full_expert(name):
    from impact_env.rollout import run_episode
    from impact_env.transport.gym_env import TransportEnv
    from planners.expert import Expert

    scenario = load_scenario(name)
    plan = Plan.from_dict(json.loads((PLANS / f"{name}.json").read_text()))
    expert = Expert(scenario, plan=plan)
    result = run_episode(TransportEnv(scenario), expert, seed=0)
    assert result.success and result.robustness >= 0.9 * plan.robustness, (name, result.robustness)
    assert not expert.report()["unplanned_contacts"]
