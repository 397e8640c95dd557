"""The spatially robust MILP planner: known optima, the impact law, thrust feasibility, physics replay,
infeasibility diagnosis, and the committed plans of the shipped scenarios (tests/shipped_plans.py) against a
new solve."""

from __future__ import annotations

import copy
import os
import subprocess
import sys

import numpy as np
import pytest

from impact_env.transport.scenario import load_scenario, scenario_from_dict
from planners.errors import InfeasiblePlanError, PlanCheckError, PlannerError, PlanTimeoutError, UnsupportedSpecError
from planners.offline.spatially_robust import PlannerConfig, plan_spatially_robust
from planners.plan import Plan
from tests.replay import replay
from tests.shipped_plans import SR_SCENARIOS, objective
from tests.shipped_plans import plan as plan_now

# The geometric optimum of each shipped task, derived by hand.
# - throw_and_catch_exp: F[0,20] in(O1, goal). The robustness of "in" is the distance to the goal box's
#   boundary, at most its half-width 0.4 m (at the centre (2.5, 0)). The object can be brought there and
#   stopped by a catch (Eq. 5 admits a robot velocity that zeroes the object's), so rho* = 0.4.
# - corridor: F[0,100] in(O1, goal) & G[0,100] (every body outside W1 and W2). The goal box is 1.5 m wide:
#   at most 0.75 m. Every body can stay on x = 1, 1 m from both walls (they start there and the throw and
#   catch are along x = 1), so the walls allow 1.0 > 0.75 and rho* = min(0.75, 1.0) = 0.75.
# - obstacle_avoidance: F[0,150] in(O1, goal) & G[0,150] (every body outside obs). The goal box is 1 m wide:
#   0.5 m. The obstacle limits rho to the object's start distance to it, 1.0 m ((5.5, 5) above the face
#   y = 4), and the left corridor (x in [0.2, 3]) leaves room for 0.5 m, so rho* = min(0.5, 1.0) = 0.5.
OPTIMA = {"throw_and_catch_exp": 0.4, "corridor": 0.75, "obstacle_avoidance": 0.5}


@pytest.fixture(scope="module")
def plans(shipped_plans):
    """The committed plans (tests/data/plans/shipped/sr/); test_the_committed_plans_are_the_planners_answer
    plans them again."""
    return {name: shipped_plans.sr(name) for name in OPTIMA}


@pytest.mark.parametrize("name", list(OPTIMA))
def test_reaches_the_geometric_optimum(plans, name):
    plan = plans[name]
    assert plan.robustness == pytest.approx(OPTIMA[name], abs=1e-3)
    assert plan.planner == "sr" and plan.solver == "highs"
    assert len(plan.impacts) >= 2  # at least a throw and a catch


@pytest.mark.parametrize("name", list(OPTIMA))
def test_impact_law_in_real_velocities_and_plan_check(plans, name):
    scenario = load_scenario(name)
    plan = plans[name]
    plan.check(scenario, tol=1e-6)
    e = scenario.restitution
    for imp in plan.impacts:
        m_r, m_o = scenario.body(imp.robot).mass_kg, scenario.body(imp.object).mass_kg
        vr0, vr1 = np.array(imp.robot_velocity_before), np.array(imp.robot_velocity_after)
        vo0, vo1 = np.array(imp.object_velocity_before), np.array(imp.object_velocity_after)
        # Eq. (5) solved for the post-impact velocities
        s = m_r + m_o
        np.testing.assert_allclose(vo1, (1 + e) * m_r / s * vr0 + (m_o - e * m_r) / s * vo0, atol=1e-6)
        np.testing.assert_allclose(vr1, (m_r - e * m_o) / s * vr0 + (1 + e) * m_o / s * vo0, atol=1e-6)
        # and the trajectories really have these velocities on both sides of the impact
        body = plan.bodies[imp.object]
        np.testing.assert_allclose(body.velocity(imp.time_s + 1e-6), vo1, atol=1e-6)
        np.testing.assert_allclose(body.velocity(imp.time_s - 1e-6), vo0, atol=1e-6)


@pytest.mark.parametrize("name", list(OPTIMA))
def test_plans_are_flyable_within_thrust_limits(plans, name):
    """Sampled densely, every robot's planned acceleration needs at most half its thrust limit per axis."""
    scenario = load_scenario(name)
    plan = plans[name]
    t = np.linspace(0, scenario.tf_s, 4001)
    for robot in scenario.robots:
        force = robot.mass_kg * np.abs(plan.bodies[robot.name].acceleration(t)).max(axis=0)
        assert np.all(force <= 0.5 * np.array(robot.thrust_limit_N) + 1e-6)
        speed = np.abs(plan.velocity(robot.name, t)).max(axis=0)
        assert np.all(speed <= np.array(robot.velocity_bound_mps) + 1e-6)


@pytest.mark.parametrize("name", ["throw_and_catch_exp", "corridor", "obstacle_avoidance"])
def test_replayed_in_the_simulator_the_plan_satisfies_the_task(plans, name):
    """Robots follow the plan exactly (tests/replay.py) and the object, moved only by the impacts, does what
    the plan says.

    For the two throw-and-catch tasks every impact reproduces the planned time (within a few substeps)
    and post-impact velocity, and the simulated trace satisfies the task with the planned robustness.
    obstacle_avoidance chains four impacts in 2D: open loop, the first impact is exact but a few substeps of
    timing error at each later one compound (a robot that follows its plan blindly pushes a little too
    long), which is what the closed-loop expert (replanner + MPC) corrects; here only its first impact is
    required to be exact.
    """
    scenario = load_scenario(name)
    plan = plans[name]
    trace, rho, events = replay(plan, scenario)
    robots = {r.name for r in scenario.robots}
    hits = sorted((e for e in events if "O1" in (e.a, e.b) and {e.a, e.b} & robots), key=lambda e: e.time_s)
    exact = plan.impacts if name != "obstacle_avoidance" else plan.impacts[:1]
    for planned, simulated in zip(exact, hits):
        assert simulated.time_s == pytest.approx(planned.time_s, abs=0.05)
        np.testing.assert_allclose(simulated.velocity_after("O1"), planned.object_velocity_after, atol=0.02)
    if name != "obstacle_avoidance":
        assert len(hits) == len(plan.impacts)
        assert rho > 0, f"simulated robustness {rho}"
        assert rho == pytest.approx(plan.robustness, abs=0.02)


def test_json_round_trip(plans, tmp_path):
    plan = plans["corridor"]
    path = plan.save(tmp_path / "plan.json")
    again = Plan.load(path)
    assert again.to_dict() == plan.to_dict()
    again.check(load_scenario("corridor"))
    data = again.to_dict()
    assert {"scenario", "planner", "robustness", "solve_time_s", "mip_gap", "solver", "impacts", "bodies"} <= set(data)
    assert {"time", "robot", "object", "position", "object_velocity_before", "object_velocity_after",
            "robot_velocity_before", "robot_velocity_after"} <= set(data["impacts"][0])


def test_check_catches_a_broken_impact_law_and_thrust(plans):
    scenario = load_scenario("throw_and_catch_exp")
    plan = copy.deepcopy(plans["throw_and_catch_exp"])
    imp = plan.impacts[0]
    imp.object_velocity_after = (imp.object_velocity_after[0] * 1.1, imp.object_velocity_after[1])
    with pytest.raises(PlanCheckError, match="momentum|restitution|recorded"):
        plan.check(scenario)
    plan = copy.deepcopy(plans["throw_and_catch_exp"])
    seg = plan.bodies["R1"].segments[1]
    seg.control_points[2] += [3.0, 0.0]  # a sharp kink: needs far more than 2.8 N
    with pytest.raises(PlanCheckError, match="thrust limit"):
        plan.check(scenario)


def test_qp_smoothing_keeps_the_optimum_and_lowers_acceleration(plans):
    scenario = load_scenario("corridor")
    smooth = plan_spatially_robust(scenario, PlannerConfig(smooth=True))
    assert smooth.robustness == pytest.approx(0.75, abs=1e-3)
    smooth.check(scenario)

    def energy(plan):
        t = np.linspace(0, scenario.tf_s, 2001)
        return sum(np.sum(plan.bodies[r.name].acceleration(t) ** 2) for r in scenario.robots)

    def hits(plan):
        return {(i.robot, i.time_s) for i in plan.impacts}

    same_binaries = hits(smooth) == hits(plans["corridor"])
    if same_binaries:
        assert energy(smooth) <= energy(plans["corridor"]) * (1 + 1e-6)


def test_warm_start_reaches_the_same_optimum(plans):
    scenario = load_scenario("throw_and_catch_exp")
    again = plan_spatially_robust(scenario, PlannerConfig(warm_start=plans["throw_and_catch_exp"]))
    assert again.robustness == pytest.approx(0.4, abs=1e-3)


def _lab(**changes) -> dict:
    from importlib.resources import files

    import tomllib

    data = tomllib.loads(files("impact_env.transport.scenarios").joinpath("throw_and_catch_exp.toml").read_text())
    data.update(changes)
    return data


def test_goal_inside_an_obstacle_is_infeasible():
    data = _lab()
    data["obstacles"] = [{"name": "block", "box": [2.0, 3.0, -0.5, 0.5]}]
    del data["objects"][0]["final_position_m"]  # else the scenario loader already rejects the file
    with pytest.raises(InfeasiblePlanError) as info:
        plan_spatially_robust(scenario_from_dict(data))
    assert "task: F[0, 20] in(O1, goal)" in info.value.groups
    assert "obstacle clearance" in info.value.groups
    assert "conflict" in str(info.value)


def test_horizon_too_short_is_infeasible():
    data = _lab(tf_s=3.0, task="F[0,3] in(O1, goal)")
    with pytest.raises(InfeasiblePlanError) as info:
        plan_spatially_robust(scenario_from_dict(data))
    groups = info.value.groups
    assert "task: F[0, 3] in(O1, goal)" in groups
    assert {"velocity bounds", "thrust limits"} & set(groups)


def test_nested_temporal_operators_are_rejected():
    data = _lab(task="G[0,10] F[0,5] in(O1, goal)")
    with pytest.raises(UnsupportedSpecError, match="nested"):
        plan_spatially_robust(scenario_from_dict(data))


def test_time_limit_raises_with_the_best_plan_or_none():
    with pytest.raises(PlanTimeoutError) as info:
        plan_spatially_robust(load_scenario("obstacle_avoidance"), PlannerConfig(time_limit_s=0.05))
    if info.value.plan is not None:
        assert info.value.mip_gap is not None and info.value.mip_gap > 0


def test_stage_two_is_cut_by_work_not_time_so_load_does_not_change_the_plan(plans):
    """The corridor's stage 2 needs ~5 s unloaded; a time limit there gave a different plan on a busy machine.
    Plan it again with every core busy: the node-limited stage 2 must give the same plan, bit for bit."""
    first = plans["corridor"]
    assert first.stats["refine_status"] in ("node_limit", "optimal")
    assert first.stats["refine_objective"] == pytest.approx(2.0, abs=0.01)  # two impacts, tiny acceleration term
    hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(os.cpu_count() or 1)]
    try:
        again = plan_spatially_robust(load_scenario("corridor"))
    finally:
        for hog in hogs:
            hog.kill()
            hog.wait()
    assert again.fingerprint() == first.fingerprint()
    assert again.stats["refine_status"] == first.stats["refine_status"]


def test_refine_nodes_is_checked_and_zero_skips_stage_two():
    with pytest.raises(PlannerError, match=r"PlannerConfig.refine_nodes must be None \(no limit\) or an integer >= 0"):
        plan_spatially_robust(load_scenario("corridor"), PlannerConfig(refine_nodes=-1))
    plan = plan_spatially_robust(load_scenario("throw_and_catch_exp"), PlannerConfig(refine_nodes=0))
    assert plan.stats["refine_status"] == "skipped"
    assert plan.robustness == pytest.approx(OPTIMA["throw_and_catch_exp"], abs=1e-3)


def test_every_shipped_scenario_has_a_committed_plan():
    """A scenario added to impact_env/transport/scenarios/ gets its plan in tests/data/plans/shipped/sr/ (and a
    place in SR_SCENARIOS, so that the test below plans it again): `python -m tests.shipped_plans sr:<name>`."""
    from impact_env.transport.scenario import scenario_names
    from tests.shipped_plans import path

    assert sorted(SR_SCENARIOS) == scenario_names()
    assert [name for name in SR_SCENARIOS if not path("sr", name).exists()] == []


@pytest.mark.slow
@pytest.mark.parametrize("name", SR_SCENARIOS)
def test_the_committed_plans_are_the_planners_answer(shipped_plans, name, record_property):
    """Each shipped scenario planned again with the committed files' options (tests/shipped_plans.py): the
    same plan, bit for bit; or, where the solver stopped at another optimum among ties (another machine's
    thread count), a checked plan proven optimal with the same rho. Keeps the files the tests fly honest."""
    committed = shipped_plans.sr(name)
    again = plan_now("sr", name)
    again.check(load_scenario(name), tol=1e-6)
    assert again.planner == committed.planner == "sr" and again.solver == committed.solver
    same = again.fingerprint() == committed.fingerprint()
    record_property("same_plan", same)
    if not same:
        assert again.mip_gap <= 1e-4 and committed.mip_gap <= 1e-4
        assert objective(again) == pytest.approx(objective(committed), rel=2e-4, abs=1e-6)
