"""The scenarios shipped for issue 22's kinds of task (a narrow gap with a time window, one robot serving two
objects, a long sequence of timed visits ending at rest, robots starting within 5 cm of walls, four robots and
two objects): each loads, its committed plan (tests/data/plans/shipped/sr/; planned again, slow, by
tests/planners/offline/test_spatially_robust.py) is proven with rho > 0 and every hand-over flyable, the
robustness benchmark's plan (results/robustness/plans/) has the same rho, and the committed plan delivers
nominally with the full expert."""

from __future__ import annotations

import json

import pytest

from impact_env.transport.scenario import load_scenario
from planners.offline.config import HandoverConfig
from planners.plan import Plan
from planners.plan.handover import unflyable_handovers
from tests.paths import ROOT

PLANS = ROOT / "results" / "robustness" / "plans"
# name -> (the planned rho in m, impacts)
NEW = {"narrow_gap": (0.15, 4), "one_robot_two_objects": (0.4, 2), "wall_start": (0.4, 2),
       "timed_visits": (0.1564, 8), "four_robots": (0.5, 5)}


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


@pytest.mark.parametrize("name", list(NEW))
def test_each_committed_plan_has_a_proven_positive_robustness(shipped_plans, name):
    scenario = load_scenario(name)
    plan = shipped_plans.sr(name)
    rho, impacts = NEW[name]
    assert plan.robustness == pytest.approx(rho, abs=1e-3) and rho > 0 and plan.mip_gap < 1e-3
    assert len(plan.impacts) == impacts
    assert unflyable_handovers(plan, scenario, HandoverConfig().margin) == []
    cached = Plan.from_dict(json.loads((PLANS / f"{name}.json").read_text()))
    assert cached.robustness == pytest.approx(plan.robustness, abs=1e-6)


@pytest.mark.slow
@pytest.mark.parametrize("name", list(NEW))
def test_each_plan_flies_nominally_with_the_full_expert(shipped_plans, name):
    from impact_env.rollout import run_episode
    from impact_env.transport.gym_env import TransportEnv
    from planners.expert import Expert

    scenario = load_scenario(name)
    plan = shipped_plans.sr(name)
    expert = Expert(scenario, plan=plan)
    result = run_episode(TransportEnv(scenario), expert, seed=0)
    assert result.success and result.robustness >= 0.9 * plan.robustness, (name, result.robustness)
    assert not expert.report()["unplanned_contacts"]
