"""Hand-overs (planners/plan/handover.py): the least time a disc robot needs to get round an object between
two of its impacts, and the offline planners' refusal or repair of a plan that leaves less."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from impact_env.transport.scenario import load_scenario
from planners.errors import InfeasiblePlanError, PlannerError, UnflyableHandoverError
from planners.offline.config import HandoverConfig, PlannerConfig
from planners.offline.spatially_robust import plan_spatially_robust
from planners.online.side_switch import side_switches
from planners.plan import Plan, PlannedImpact
from planners.plan.handover import handovers, least_handover_time_s, least_time_1d_s, unflyable_handovers
from tests.paths import DATA

MARGIN = HandoverConfig().margin


def impact(t, robot, obj, v_obj_before, v_obj_after, e=0.6):
    """A planned impact of equal masses (Eq. 5): the robot's velocities from the object's change."""
    vo0, vo1 = np.asarray(v_obj_before, float), np.asarray(v_obj_after, float)
    m3 = (1 + e) / 2  # equal masses: the object gains m3 (v_R - v_O)
    vr0 = vo0 + (vo1 - vo0) / m3
    vr1 = vo0 + vr0 - vo1  # momentum
    return PlannedImpact(t, robot, obj, (0.0, 0.0), tuple(vo0), tuple(vo1), tuple(vr0), tuple(vr1))


def plan_with(*impacts):
    return Plan("two_objects", "sr", 0.0, {}, list(impacts))


@pytest.fixture(scope="module")
def two_objects():
    return load_scenario("two_objects")


# ------------------------------------------------------------------------------------ the 1-D closed form
def test_least_time_1d_closed_forms():
    assert least_time_1d_s(1.0, 0.0, 0.0, 1.0) == pytest.approx(2.0)  # rest to rest: 2 sqrt(L / a)
    assert least_time_1d_s(1.0, 0.0, 0.0, 1.0, -0.5, 0.5) == pytest.approx(1 / 0.5 + 0.5 / 1)  # with a cruise
    # a reversal: from 0.3 m/s forward to 0.3 m/s forward, ending 1 m behind
    # (brake through zero to -sqrt(1.09) m/s and back: the mirror of speeding up from -0.3 m/s)
    assert least_time_1d_s(-1.0, 0.3, 0.3, 1.0) == pytest.approx(2 * math.sqrt(1.09) + 0.6)
    # faster than cruising: 0.5 m at 0.3 m/s takes 1.67 s; speeding up and braking back takes 1.48 s
    assert least_time_1d_s(0.5, 0.3, 0.3, 0.1) == pytest.approx(2 * (math.sqrt(0.05 + 0.09) - 0.3) / 0.1)
    assert least_time_1d_s(0.5, 0.4, 0.0, 1.0, -0.3, 0.3) == math.inf  # starts faster than the bound
    assert least_time_1d_s(1.0, 0.0, 0.0, 0.0) == math.inf  # no thrust


def test_least_time_1d_is_the_least_feasible_duration():
    """Against a time-discretised LP (piecewise constant acceleration): feasible just above the closed form's
    time, infeasible at every duration tried below it."""
    scipy_optimize = pytest.importorskip("scipy.optimize")

    def feasible(duration, distance, w0, w1, accel, low, high, n=200):
        h = duration / n
        before = np.tril(np.ones((n, n)), -1) * h  # v_k - w0, k = 0..n-1
        after = np.tril(np.ones((n, n))) * h  # v_{k+1} - w0
        a_eq = np.array([np.full(n, h), 0.5 * h * (before + after).sum(axis=0)])
        b_eq = np.array([w1 - w0, distance - duration * w0])
        a_ub = np.vstack([after, -after])
        b_ub = np.concatenate([np.full(n, high - w0), np.full(n, w0 - low)])
        res = scipy_optimize.linprog(np.zeros(n), A_ub=a_ub, b_ub=b_ub, A_eq=a_eq, b_eq=b_eq,
                                     bounds=[(-accel, accel)] * n, method="highs")
        return res.status == 0

    rng = np.random.default_rng(3)
    for _ in range(12):
        accel, high, low = rng.uniform(0.05, 0.3), rng.uniform(0.1, 0.5), -rng.uniform(0.1, 0.5)
        w0, w1, distance = rng.uniform(low, high), rng.uniform(low, high), rng.uniform(-1.5, 1.5)
        t = least_time_1d_s(distance, w0, w1, accel, low, high)
        assert feasible(1.01 * t + 1e-3, distance, w0, w1, accel, low, high)
        shortest = abs(w1 - w0) / accel
        for s in np.linspace(shortest + 1e-3, 0.98 * t, 6):
            assert s >= 0.98 * t or not feasible(s, distance, w0, w1, accel, low, high), (distance, w0, w1, s, t)


# --------------------------------------------------------------------------------- getting round an object
def test_push_then_stop_from_the_front_needs_more_than_the_old_estimate(two_objects):
    """The issue's case: R1 pushes O1 to 0.162 m/s and must stop it from the front 10 s later. Getting round
    as the arc flown at the speed bound less the object's speed (the mission's side-switch estimate before
    the two layers shared this test) takes 9.1 s; with the thrust it takes at least 9.78 s, and with the
    margin more than the 10 s there are. The mission's side switch is this hand-over."""
    push, stop = impact(0.0, "R1", "O1", (0, 0), (0.162, 0)), impact(10.0, "R1", "O1", (0.162, 0), (0, 0))
    assert math.pi * 0.4 / (0.3 - 0.162) == pytest.approx(9.1, abs=0.05)  # the old arc estimate
    (h,) = handovers(plan_with(push, stop), two_objects)
    assert side_switches(plan_with(push, stop), two_objects) == [h]
    # along the push: from 0.4 m behind at -0.12 m/s to 0.4 m in front at -0.2 m/s (relative), at 1/6 m/s^2,
    # the relative speed at most 0.3 - 0.162 m/s
    a, cap, w0, w1 = 2.8 / 16.8, 0.3 - 0.162, -0.6 * 0.162 / 0.8, -0.162 / 0.8
    up, down = (cap - w0) / a, (cap - w1) / a
    cruise = (0.8 - (cap ** 2 - w0 ** 2) / (2 * a) - (cap ** 2 - w1 ** 2) / (2 * a)) / cap
    assert h.needed_s == pytest.approx(up + down + cruise, rel=1e-9)
    assert h.needed_s == pytest.approx(9.78, abs=0.01)
    assert (h.robot, h.object, h.t1_s, h.t2_s, h.available_s) == ("R1", "O1", 0.0, 10.0, 10.0)
    assert h.angle_rad == pytest.approx(math.pi) and not h.flyable(MARGIN) and h.flyable(0.0)
    assert unflyable_handovers(plan_with(push, stop), two_objects, MARGIN) == [h]
    assert "needs at least 9.78 s (14.67 s with the 50 % margin), has 10.00 s" in h.describe(MARGIN)


def test_an_object_faster_than_the_robot_can_be_is_never_got_round(two_objects):
    push, stop = impact(0.0, "R1", "O1", (0, 0), (0.32, 0)), impact(60.0, "R1", "O1", (0.32, 0), (0, 0))
    (h,) = handovers(plan_with(push, stop), two_objects)
    assert h.needed_s == math.inf and not h.flyable(0.0) and h.to_dict()["needed_s"] is None
    assert "can never get round" in h.describe(MARGIN)


def test_without_a_speed_bound_only_the_thrust_limits(two_objects):
    import dataclasses

    free = dataclasses.replace(two_objects.body("R1"), velocity_bound_mps=None)
    push, stop = impact(0.0, "R1", "O1", (0, 0), (0.32, 0)), impact(60.0, "R1", "O1", (0.32, 0), (0, 0))
    assert 0 < least_handover_time_s(free, two_objects.body("O1"), push, stop) < 20
    # a heading of 45 degrees turns the thrust box: more thrust along the push, so less time
    turned = dataclasses.replace(free, heading_rad=math.pi / 4)
    assert least_handover_time_s(turned, two_objects.body("O1"), push, stop) < \
        least_handover_time_s(free, two_objects.body("O1"), push, stop)


@pytest.mark.parametrize("impacts", [
    # two pushes the same way
    [impact(8.0, "R1", "O1", (0.0, 0.0), (0.1, 0.0)), impact(20.0, "R1", "O1", (0.1, 0.0), (0.2, 0.01))],
    # the push and the stop by different robots
    [impact(8.0, "R2", "O2", (0.0, 0.0), (-0.13, 0.0)), impact(28.0, "R1", "O2", (-0.13, 0.0), (0.0, 0.0))],
    # another robot's impact on O1 in between
    [impact(5.0, "R1", "O1", (0.0, 0.0), (0.1, 0.0)), impact(9.0, "R2", "O1", (0.1, 0.0), (0.1, 0.1)),
     impact(15.0, "R1", "O1", (0.1, 0.1), (0.0, 0.0))],
    # R1 hits O2 in between: its next impact is not on O1
    [impact(5.0, "R1", "O1", (0.0, 0.0), (0.1, 0.0)), impact(9.0, "R1", "O2", (0.0, 0.0), (0.1, 0.1)),
     impact(15.0, "R1", "O1", (0.1, 0.0), (0.0, 0.0))],
    # a perpendicular second change
    [impact(5.0, "R1", "O1", (0.0, 0.0), (0.1, 0.0)), impact(15.0, "R1", "O1", (0.1, 0.0), (0.1, 0.1))],
])
def test_no_handover(impacts, two_objects):
    assert handovers(plan_with(*impacts), two_objects) == []


def test_the_shipped_plans_handovers_have_time():
    """The committed benchmark plans of relay and obstacle_avoidance each have one hand-over, with the time
    it needs and the margin (10 s for 5.95 s, 40 s for 5.7 s: the projections on the axes ask more than those on
    the normals alone, 5.52 and 4.9 s); their plans do not change (the repair never runs on them)."""
    root = DATA / "plans" / "robustness"
    needed = {}
    for name in ("relay", "obstacle_avoidance", "two_objects"):
        plan = Plan.from_dict(json.loads((root / f"{name}.json").read_text()))
        found = handovers(plan, load_scenario(name))
        assert all(h.flyable(MARGIN) for h in found)
        needed[name] = [(h.robot, h.t1_s, h.t2_s, round(h.needed_s, 2)) for h in found]
    assert needed == {"relay": [("R3", 15.0, 25.0, 5.95)], "obstacle_avoidance": [("R2", 50.0, 90.0, 5.7)],
                      "two_objects": []}


# ------------------------------------------------------------------------------------ the offline planner
@pytest.fixture(scope="module")
def push_and_stop():
    """tests/data/push_and_stop.toml planned without the check (the planner before it) and with it."""
    scenario = load_scenario(DATA / "push_and_stop.toml")
    return scenario, plan_spatially_robust(scenario, PlannerConfig(handover=None)), plan_spatially_robust(scenario)


def test_the_planner_without_the_check_returns_an_unflyable_handover(push_and_stop):
    """The failure of the issue, reproduced: a proven-optimal plan in which R1 pushes O1 at 6 s and stops it
    from the front at 18 s, 12 s later, where getting round takes at least 9.53 s (14.3 s with the margin)."""
    scenario, plain, _ = push_and_stop
    assert plain.mip_gap < 1e-4 and plain.robustness == pytest.approx(0.3, abs=1e-6)
    (h,) = unflyable_handovers(plain, scenario, MARGIN)
    assert (h.robot, h.object, h.t1_s, h.t2_s) == ("R1", "O1", 6.0, 18.0)
    assert h.needed_s == pytest.approx(9.53, abs=0.01)


def test_the_planner_repairs_it(push_and_stop):
    """With the check (the default) the planner cuts that hand-over and re-solves: R2 stops O1, with the same
    robustness, and the plan says what was cut."""
    scenario, plain, plan = push_and_stop
    assert unflyable_handovers(plan, scenario, MARGIN) == []
    assert plan.robustness == pytest.approx(plain.robustness, abs=1e-6)
    assert [(i.robot, i.object) for i in plan.impacts] == [("R1", "O1"), ("R2", "O1")]
    (cut,) = plan.stats["handovers_cut"]
    assert (cut["robot"], cut["t1_s"], cut["t2_s"]) == ("R1", 6.0, 18.0)
    assert cut["needed_s"] == pytest.approx(9.53, abs=0.01) and cut["available_s"] == 12.0
    assert Plan.from_dict(plan.to_dict()).stats["handovers_cut"] == plan.stats["handovers_cut"]  # in the file


def test_with_no_repairs_the_planner_refuses_and_says_why(push_and_stop):
    scenario, _, _ = push_and_stop
    with pytest.raises(UnflyableHandoverError) as info:
        plan_spatially_robust(scenario, PlannerConfig(handover=HandoverConfig(repairs=0)))
    err = info.value
    assert isinstance(err, InfeasiblePlanError)
    assert "R1 round O1 between its impacts at 6.00 s and 18.00 s (180 degrees apart): needs at least 9.53 s " \
           "(14.29 s with the 50 % margin), has 12.00 s" in str(err)
    assert [(h.robot, h.object, h.t1_s, h.t2_s) for h in err.handovers] == [("R1", "O1", 6.0, 18.0)]
    assert err.plan is not None and err.plan.impacts[1].robot == "R1"


def test_handover_config_is_checked():
    with pytest.raises(PlannerError, match="HandoverConfig.margin"):
        HandoverConfig(margin=-0.1)
    with pytest.raises(PlannerError, match="HandoverConfig.repairs"):
        HandoverConfig(repairs=1.5)
    with pytest.raises(PlannerError, match="PlannerConfig.handover must be None"):
        PlannerConfig(handover=0.5)


@pytest.mark.slow
def test_the_paper_stack_flies_the_repaired_plan_and_not_the_unflyable_one(push_and_stop):
    """Closed loop, nominal: with the unflyable hand-over R1 hits O1 from behind again at 17.6 s instead of
    stopping it (-1.2 m); the repaired plan delivers with its planned 0.3 m."""
    from impact_env.rollout import run_episode
    from impact_env.transport.gym_env import TransportEnv
    from planners.expert import Expert, ExpertConfig

    scenario, plain, plan = push_and_stop
    results = {}
    for name, p in (("plain", plain), ("repaired", plan)):
        expert = Expert(scenario, plan=p, config=ExpertConfig.paper())
        results[name] = run_episode(TransportEnv(scenario), expert, seed=0)
    assert not results["plain"].success and results["plain"].robustness < -1.0
    assert results["repaired"].success and results["repaired"].robustness == pytest.approx(0.3, abs=0.01)


# ----------------------------------------------------------------------------------------- mission re-plans
def test_a_mission_replan_is_repaired_before_the_mission_sees_it():
    """The mission's side-switch regression case (tests/planners/online/test_mission_side_switch.py: two_objects,
    simulator restitution 0.3, the check at 10.1 s): the point-mass re-plan has R1 round O1 and R2 round O2, which the
    mission refuses. With the hand-over check (the default) the planner cuts them itself, and the mission, on
    the same test with the same margin, accepts the repaired re-plan (0.129 m point-mass robustness, found with
    the end states relaxed; R2 pushes O2 at 18.6 s and stops it at 31.5 s, 12.8 s for the 6.6 s it needs).

    Until both layers shared one test, the planner's bound projected the way round on the first contact normal
    only and passed a re-plan in which R2 stops O2 8.5 s after an oblique push (5.7 s by that projection; 8.1 s
    along x, which a trajectory round the disc matches: :func:`test_the_least_time_is_the_least_time_round_the_disc`);
    the mission's arc estimate (7.5 s, 9.4 s with its margin) refused it, so the mission kept the offline plan."""
    from planners.online.bookkeeping import ImpactBook
    from planners.online.mission import MissionConfig, MissionPlanner
    from planners.online.side_switch import unflyable_side_switches

    case = json.loads((DATA / "two_objects_replan_at_10s.json").read_text())
    scenario = load_scenario(case["scenario"])
    plan = Plan.from_dict(case["plan"])
    planner = MissionPlanner(scenario, plan, MissionConfig(), aim_final_position=True)
    planner.trace = list(np.array(case["trace_m"])[:-1])
    book = ImpactBook(plan.impacts, tolerance_s=2.0)
    book.done = {0}
    new = planner.step(case["time_s"], np.array(case["states"]), {n: i for i, n in enumerate(case["bodies"])}, plan,
                       book, True, None)
    assert new is not None and planner.records[0].status == "accepted (end states relaxed)"
    spliced, _ = new
    assert unflyable_side_switches(spliced, scenario, case["time_s"]) == []
    assert unflyable_handovers(spliced, scenario, MARGIN) == []
    assert planner.records[0].new_robustness == pytest.approx(0.1286, abs=1e-3)
    assert {h["robot"] for h in spliced.stats["handovers_cut"]} >= {"R1", "R2"}
    r2 = next(h for h in handovers(spliced, scenario) if h.robot == "R2")
    assert (r2.t1_s, r2.t2_s) == pytest.approx((18.64, 31.46), abs=0.01) and r2.flyable(MARGIN)
    assert planner.unflyable(spliced, case["time_s"], np.array(case["states"]),
                             {n: i for i, n in enumerate(case["bodies"])}, None) == []


@pytest.mark.slow
def test_the_full_expert_flies_the_repaired_mission_replan():
    """The whole regression episode with the default planner: the re-plan at 10.1 s of the test above is
    accepted and flown to +0.169 m (+0.09 m keeping the offline plan, as the mission does when it refuses a
    side-switch re-plan). The +0.14 m this test asked before was measured at 3dfc5fa, before later changes to
    the online layer; on main before this test's fix the episode already accepted this same re-plan (R2's stop
    at 31.5 s, 12.8 s after its push) and flew it to +0.169 m, deterministically."""
    from impact_env.rollout import run_episode
    from impact_env.transport.gym_env import TransportEnv
    from planners.expert import Expert

    case = json.loads((DATA / "two_objects_replan_at_10s.json").read_text())
    scenario = load_scenario(case["scenario"])
    expert = Expert(scenario, plan=Plan.from_dict(case["plan"]))
    result = run_episode(TransportEnv(scenario, restitution=0.3), expert, seed=0)
    assert result.success and result.robustness == pytest.approx(0.169, abs=0.005)
    assert [r["status"] for r in expert.report()["mission"]["records"]][-1] == "accepted (end states relaxed)"


# ------------------------------------------------------------------------ one test of flyability, two layers
def round_the_disc(duration_s, robot, v_obj, d, r0, u0, r1, u1, arc, steps=80, rounds=25):
    """A trajectory in the object's frame from (r0, u0) to (r1, u1) in ``duration_s``, piecewise-constant thrust
    within the robot's box (heading 0), its world velocity within its speed bound, outside the disc |r| >= d at
    every sample, going round by ``arc`` (rad): linear programs with the disc replaced by tangent half-planes
    (each a subset of the outside), moved to the last solution's angles. True if one is found: a witness that
    the way round takes at most ``duration_s``."""
    scipy_optimize = pytest.importorskip("scipy.optimize")
    h, n = duration_s / steps, 2 * steps + 1  # thrusts a_k (x, y), then the slack of the half-planes
    accel = np.asarray(robot.thrust_limit_N) / robot.mass_kg
    vel = [np.kron(np.r_[np.full(j, h), np.zeros(steps - j)], np.eye(2)) for j in range(steps + 1)]
    pos = [np.kron(np.r_[h * h * (j - np.arange(j) - 0.5), np.zeros(steps - j)], np.eye(2)) for j in range(steps + 1)]
    pad = np.zeros((2, 1))
    a_eq = np.vstack([np.hstack([vel[-1], pad]), np.hstack([pos[-1], pad])])
    b_eq = np.r_[u1 - u0, r1 - r0 - u0 * duration_s]
    bound = np.asarray(robot.velocity_bound_mps)
    a_v = np.vstack([np.hstack([s * vel[j], pad]) for j in range(1, steps) for s in (1, -1)])
    b_v = np.concatenate([s * -(u0 + v_obj) + bound for _ in range(1, steps) for s in (1, -1)])
    start = math.atan2(r0[1], r0[0])
    normals = [np.array([math.cos(start + arc * j / steps), math.sin(start + arc * j / steps)])
               for j in range(steps + 1)]
    cost = np.r_[np.zeros(n - 1), 1.0]
    for _ in range(rounds):
        a_d = np.array([np.r_[-(m @ pos[j]), -1.0] for j, m in enumerate(normals) if 0 < j < steps])
        b_d = np.array([m @ (r0 + u0 * j * h) - d for j, m in enumerate(normals) if 0 < j < steps])
        res = scipy_optimize.linprog(cost, A_ub=np.vstack([a_v, a_d]), b_ub=np.r_[b_v, b_d], A_eq=a_eq, b_eq=b_eq,
                                     bounds=[(-accel[i % 2], accel[i % 2]) for i in range(n - 1)] + [(0, None)],
                                     method="highs")
        if res.status != 0:
            return False
        if res.x[-1] < 1e-7:
            return True
        points = [r0 + u0 * j * h + pos[j] @ res.x[:-1] for j in range(steps + 1)]
        normals = [p / np.linalg.norm(p) for p in points]
    return False


@pytest.fixture(scope="module")
def point_mass_replan():
    """The regression case's re-plan at 10.1 s made without the planner's hand-over check, which the mission
    accepts only when side switches are allowed, and its hand-over of R2 round O2."""
    from planners.online.bookkeeping import ImpactBook
    from planners.online.mission import MissionConfig, MissionPlanner

    case = json.loads((DATA / "two_objects_replan_at_10s.json").read_text())
    scenario = load_scenario(case["scenario"])
    plan = Plan.from_dict(case["plan"])
    planner = MissionPlanner(scenario, plan, MissionConfig(allow_side_switches=True), PlannerConfig(handover=None),
                             aim_final_position=True)
    planner.trace = list(np.array(case["trace_m"])[:-1])
    book = ImpactBook(plan.impacts, tolerance_s=2.0)
    book.done = {0}
    states, index = np.array(case["states"]), {n: i for i, n in enumerate(case["bodies"])}
    spliced, _ = planner.step(case["time_s"], states, index, plan, book, True, None)
    (r2,) = [h for h in handovers(spliced, scenario) if h.robot == "R2"]
    return case, scenario, spliced, r2, (states, index)


def test_the_least_time_is_the_least_time_round_the_disc(two_objects):
    """R2's hand-over in the regression case's re-plan as the planner repaired it before this test
    (``data/two_objects_oblique_handover.json``): R2 pushes O2 obliquely (20 degrees off x) at 22.9 s and must
    stop it from the front 8.54 s later. The projection on the first normal alone (the bound then) says 5.68 s,
    so the 50 % margin (8.51 s) passed it, and the mission refused it by its own arc estimate (7.5 s). Projected on
    x, where the speed box gives the object's 0.15 m/s away from the robot in full, it takes at least 8.13 s, and
    a trajectory round the disc at full thrust exists in 1 % more: the bound is the least time, the margin is
    not there (the mission was right to refuse it), and with 80 % of the thrust no way round exists at all."""
    from planners.plan import handover as module

    stored = json.loads((DATA / "two_objects_oblique_handover.json").read_text())
    first, second = (PlannedImpact(**{k: tuple(v) if isinstance(v, list) else v for k, v in i.items()})
                     for i in stored["impacts"])
    (h,) = handovers(plan_with(first, second), two_objects)
    assert (h.robot, h.t1_s, h.t2_s) == ("R2", pytest.approx(22.914, abs=1e-3), pytest.approx(31.457, abs=1e-3))
    robot, obj = two_objects.body("R2"), two_objects.body("O2")
    d = robot.radius_m + obj.radius_m
    n1 = module._unit(np.subtract(first.object_velocity_after, first.object_velocity_before))
    n2 = module._unit(np.subtract(second.object_velocity_after, second.object_velocity_before))
    v_obj = np.asarray(first.object_velocity_after)
    u0 = np.subtract(first.robot_velocity_after, first.object_velocity_after)
    u1 = np.subtract(second.robot_velocity_before, second.object_velocity_before)
    r0, r1 = -d * n1, -d * n2
    normal_only = module._projected_bvp_s(robot, v_obj, n1, -d, float(u0 @ n1), float(r1 @ n1), float(u1 @ n1))
    assert normal_only == pytest.approx(5.68, abs=0.01) and normal_only * (1 + MARGIN) < h.available_s
    assert h.needed_s == pytest.approx(8.13, abs=0.01) and not h.flyable(MARGIN) and h.flyable(0.0)
    angle = math.remainder(math.atan2(r1[1], r1[0]) - math.atan2(r0[1], r0[0]), 2 * math.pi)
    ways = (angle, angle - math.copysign(2 * math.pi, angle))
    assert any(round_the_disc(1.01 * h.needed_s, robot, v_obj, d, r0, u0, r1, u1, arc) for arc in ways)
    # (never below the bound: the bound is a relaxation, so a witness under it would show it wrong)
    assert not any(round_the_disc(0.9 * h.needed_s, robot, v_obj, d, r0, u0, r1, u1, arc) for arc in ways)
    import dataclasses

    weaker = dataclasses.replace(robot, thrust_limit_N=tuple(0.8 * f for f in robot.thrust_limit_N))
    assert least_handover_time_s(weaker, obj, first, second) > h.available_s


def test_a_truly_unflyable_side_switch_is_refused_by_both_layers(two_objects, point_mass_replan):
    """The closed-form case: R1 pushes O1 along x to 0.162 m/s and stops it from the front; getting round takes
    9.78 s (the 1-D least time along x, test above), 14.67 s with the margin. With 14 s the offline planner's
    check (what ``solve_to_plan`` runs) and the mission's both refuse it; with 15 s both pass it. And the
    regression case's point-mass re-plan (R2 pushes O2 at 18.6 s and stops it 8.54 s later, where getting round
    takes at least 9.81 s even at full thrust) is refused by both."""
    from planners.online.mission import MissionConfig, MissionPlanner

    index = {b.name: i for i, b in enumerate(two_objects.bodies)}
    states = np.array([[*b.position_m, 0.0, *b.velocity_mps, 0.0] for b in two_objects.bodies])
    offline = Plan.from_dict(json.loads((DATA / "plans" / "robustness" / "two_objects.json").read_text()))
    mission = MissionPlanner(two_objects, offline, MissionConfig())
    found = {}
    for gap in (14.0, 15.0):
        plan = plan_with(impact(18.0, "R1", "O1", (0, 0), (0.162, 0)),
                         impact(18.0 + gap, "R1", "O1", (0.162, 0), (0, 0)))
        (h,) = handovers(plan, two_objects)
        assert h.needed_s == pytest.approx(9.78, abs=0.01)
        planner_refuses = bool(unflyable_handovers(plan, two_objects, HandoverConfig().margin))
        reasons = [r for r in mission.unflyable(plan, 10.0, states, index, None) if r.startswith("side switch")]
        found[gap] = (planner_refuses, reasons)
    assert found == {14.0: (True, ["side switch R1 round O1 between 18.0 and 32.0 s, needs 14.7 s with the margin, "
                                   "has 14.0 s"]), 15.0: (False, [])}
    case, scenario, spliced, r2, (states, index) = point_mass_replan
    assert (r2.t1_s, r2.t2_s) == pytest.approx((18.643, 27.186), abs=1e-3) and not r2.flyable(0.0)
    assert r2.needed_s == pytest.approx(9.81, abs=0.01)
    assert r2 in unflyable_handovers(spliced, scenario, HandoverConfig().margin)
    mission = MissionPlanner(scenario, spliced, MissionConfig())
    assert any(r.startswith("side switch R2 round O2") for r in mission.unflyable(spliced, case["time_s"], states,
                                                                                   index, None))
