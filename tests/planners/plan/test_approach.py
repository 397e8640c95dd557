"""Approaches (planners/plan/approach.py): the least time a disc robot needs to get round an object on its way to
its first impact, and the offline planners' refusal or repair of a plan that leaves less."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from impact_env.transport.scenario import load_scenario
from planners.errors import InfeasiblePlanError, UnflyableHandoverError
from planners.offline.config import HandoverConfig, PlannerConfig
from planners.offline.spatially_robust import plan_spatially_robust
from planners.plan import BodyPlan, Plan, PlannedImpact, Segment
from planners.plan.approach import approaches, unflyable_approaches
from planners.plan.handover import handovers, least_time_1d_s
from tests.paths import DATA

MARGIN = HandoverConfig().margin
ACCEL = 2.8 / 16.8  # the shipped robots' thrust per axis over their mass (m/s^2)


def impact(t, robot, obj, position, v_obj_before, v_obj_after, e=0.6):
    """A planned impact of equal masses (Eq. 5): the robot's velocities from the object's change."""
    vo0, vo1 = np.asarray(v_obj_before, float), np.asarray(v_obj_after, float)
    vr0 = vo0 + (vo1 - vo0) / ((1 + e) / 2)
    return PlannedImpact(t, robot, obj, tuple(position), tuple(vo0), tuple(vo1), tuple(vr0), tuple(vo0 + vr0 - vo1))


def still(name, position, tf=60.0):
    """A robot's plan that holds it at ``position`` (one segment of degree 1)."""
    return BodyPlan(name, "robot", [Segment(0.0, tf, np.array([position, position], dtype=float))])


@pytest.fixture(scope="module")
def two_objects():
    """Two robots (R1, R2: 0.2 m, 16.8 kg, 2.8 N, 0.3 m/s per axis) and objects of 0.2 m, at rest."""
    return load_scenario("two_objects")


def starting(scenario, **positions):
    """``scenario`` with its bodies at rest at the given positions."""
    bodies = {b.name: b for b in scenario.bodies}
    moved = {n: dataclasses.replace(bodies[n], position_m=tuple(p), velocity_mps=(0.0, 0.0))
             for n, p in positions.items()}
    return dataclasses.replace(scenario, robots=tuple(moved.get(b.name, b) for b in scenario.robots),
                               objects=tuple(moved.get(b.name, b) for b in scenario.objects))


def test_the_way_round_from_the_start_is_the_least_time_along_the_push(two_objects):
    """R1 starts 0.8 m right of O1, both at rest, and must push O1 right at 12 s from its contact 0.4 m left of
    O1's centre, arriving at 0.0625 m/s relative (a push to 0.05 m/s, e = 0.6): along x it flies 1.2 m left and
    turns round, up to -0.3 m/s, a cruise, and braking through zero to +0.0625 m/s. Getting round the side
    (0.4 m out along y and back) is shorter, so the least time is the 1-D one along x, in closed form."""
    scenario = starting(two_objects, R1=(2.3, 1.5), O1=(1.5, 1.5))
    push = impact(12.0, "R1", "O1", (1.5, 1.5), (0, 0), (0.05, 0))
    (a,) = approaches(Plan("two_objects", "sr", 0.0, {}, [push]), scenario)
    w1 = 0.05 / 0.8
    up, down = 0.3 / ACCEL, (0.3 + w1) / ACCEL  # to -0.3 m/s, then from -0.3 to +w1
    cruise = (1.2 - 0.3 ** 2 / (2 * ACCEL) - (0.3 ** 2 - w1 ** 2) / (2 * ACCEL)) / 0.3
    assert a.needed_s == pytest.approx(up + down + cruise, rel=1e-9)
    assert a.needed_s == pytest.approx(least_time_1d_s(-1.2, 0.0, w1, ACCEL, -0.3, 0.3), rel=1e-9)
    assert (a.robot, a.object, a.t0_s, a.t1_s, a.by, a.available_s) == ("R1", "O1", 0.0, 12.0, None, 12.0)
    assert a.flyable(MARGIN) and not dataclasses.replace(a, t1_s=a.needed_s * 1.4).flyable(MARGIN)
    assert "R1 round O1 to its first impact at 12.00 s from its start: needs at least 6.21 s (9.32 s with the " \
           "50 % margin), has 12.00 s" in a.describe(MARGIN)
    assert unflyable_approaches(Plan("two_objects", "sr", 0.0, {}, [dataclasses.replace(push, time_s=9.0)]),
                                scenario, MARGIN)[0].t1_s == 9.0


@pytest.mark.parametrize("start", [(0.3, 1.5), (1.0, 0.6), (0.9, 2.4)])
def test_a_straight_way_past_the_object_needs_no_way_round(two_objects, start):
    """From the left, below-left or above-left of O1 the segment to the contact 0.4 m left of its centre stays
    out of the disc: nothing to get round (the plan's own way is the check of its time), and no approach is
    listed. From straight below the segment cuts into the disc just before the contact: that one is listed."""
    scenario = starting(two_objects, R1=start, O1=(1.5, 1.5))
    push = impact(3.0, "R1", "O1", (1.5, 1.5), (0, 0), (0.05, 0))
    assert approaches(Plan("two_objects", "sr", 0.0, {}, [push]), scenario) == []
    below = starting(two_objects, R1=(1.5, 0.6), O1=(1.5, 1.5))
    assert [a.robot for a in approaches(Plan("two_objects", "sr", 0.0, {}, [push]), below)] == ["R1"]


def test_after_another_robots_impact_the_way_starts_there_in_the_objects_new_frame(two_objects):
    """R2 pushes O1 at 4 s to 0.1 m/s along x; R1, waiting 0.8 m right of where O1 is then (its plan holds it
    there), pushes it on from behind at 10 s. O1 flies at 0.1 m/s after R2's impact, so in its frame R1 starts
    0.8 m ahead moving at -0.1 m/s, and has the 6 s from R2's impact: the 1-D least time along x with the
    relative speed range shifted by the object's 0.1 m/s. The time before 4 s does not count (the object was
    elsewhere), nor does the object's start frame (at rest)."""
    scenario = starting(two_objects, R1=(2.3, 1.5), R2=(0.5, 1.5), O1=(1.5, 1.5))
    first = impact(4.0, "R2", "O1", (1.5, 1.5), (0, 0), (0.1, 0))
    second = impact(10.0, "R1", "O1", (2.1, 1.5), (0.1, 0), (0.15, 0))
    plan = Plan("two_objects", "sr", 0.0, {"R1": still("R1", (2.3, 1.5))}, [first, second])
    found = approaches(plan, scenario)
    assert [(a.robot, a.by, a.t0_s, a.t1_s, a.available_s) for a in found] == [("R1", "R2", 4.0, 10.0, 6.0)]
    w1 = 0.05 / 0.8  # relative, before R1's push
    assert found[0].needed_s == pytest.approx(least_time_1d_s(-1.2, -0.1, w1, ACCEL, -0.4, 0.2), rel=1e-9)
    # 5.28 s: O1 comes toward R1 (6.21 s from rest over the same 1.2 m, the test above); 7.92 s with the margin
    assert found[0].needed_s == pytest.approx(5.28, abs=0.01)
    assert found[0].flyable(0.0) and not found[0].flyable(MARGIN)
    assert "from R2's impact at 4.00 s" in found[0].describe(MARGIN)
    # R2's own first impact comes from the left: nothing to get round
    assert all(a.robot != "R2" for a in found)


def test_an_object_faster_than_the_robot_can_be_is_never_got_in_front_of(two_objects):
    """R2 pushes O1 left at 4 s to 0.32 m/s, faster than R1's 0.3 m/s bound; R1, behind O1 (to its right), can
    push it on from behind (a clear straight way: nothing to get round) but never stop it from the front."""
    scenario = starting(two_objects, R1=(2.5, 2.5), R2=(2.5, 1.5), O1=(1.5, 1.5))
    first = impact(4.0, "R2", "O1", (1.5, 1.5), (0, 0), (-0.32, 0))
    curves = {"R1": still("R1", (2.5, 2.5))}
    push_on = impact(10.0, "R1", "O1", (-0.42, 1.5), (-0.32, 0), (-0.34, 0))
    assert approaches(Plan("two_objects", "sr", 0.0, curves, [first, push_on]), scenario) == []
    stop = impact(10.0, "R1", "O1", (-0.42, 1.5), (-0.32, 0), (0.0, 0))
    (a,) = approaches(Plan("two_objects", "sr", 0.0, curves, [first, stop]), scenario)
    assert (a.robot, a.by, a.t0_s) == ("R1", "R2", 4.0)
    assert a.needed_s == math.inf and not a.flyable(0.0) and a.to_dict()["needed_s"] is None
    assert "can never get round" in a.describe(MARGIN)


# ------------------------------------------------------------------------------------ the offline planner
@pytest.fixture(scope="module")
def round_to_push():
    """tests/data/round_to_push.toml planned without the check (the planner before it) and with it."""
    scenario = load_scenario(DATA / "round_to_push.toml")
    return scenario, plan_spatially_robust(scenario, PlannerConfig(handover=None)), plan_spatially_robust(scenario)


def test_the_planner_without_the_check_flies_through_the_object_to_its_first_impact(round_to_push):
    """A proven-optimal plan in which R1, starting above and right of O1, pushes it right at 8 s: the point R1
    flies through O1 to its contact; a disc R1 needs at least 5.94 s to get round (8.91 s with the margin)."""
    scenario, plain, _ = round_to_push
    assert plain.mip_gap < 1e-4 and plain.robustness == pytest.approx(0.3, abs=1e-6)
    assert [(i.time_s, i.robot) for i in plain.impacts] == [(8.0, "R1")]
    (a,) = unflyable_approaches(plain, scenario, MARGIN)
    assert (a.robot, a.object, a.t0_s, a.t1_s, a.by) == ("R1", "O1", 0.0, 8.0, None)
    assert a.needed_s == pytest.approx(5.94, abs=0.01)
    assert handovers(plain, scenario) == []


def test_the_planner_repairs_it(round_to_push):
    """With the check (the default) the planner cuts R1's first impact at 8 s and re-solves: the same
    robustness, an approach with its margin (R1 pushes at 10 s, and brakes O1 from the front at 24 s, a
    hand-over with its margin too, before the world's wall), and the plan says what was cut (in its file too)."""
    scenario, plain, plan = round_to_push
    assert unflyable_approaches(plan, scenario, MARGIN) == []
    assert all(h.flyable(MARGIN) for h in handovers(plan, scenario))
    assert plan.robustness == pytest.approx(plain.robustness, abs=1e-6)
    assert min(i.time_s for i in plan.impacts if i.robot == "R1") > 8.0
    cut = plan.stats["approaches_cut"]
    assert (cut[0]["robot"], cut[0]["t0_s"], cut[0]["t1_s"], cut[0]["by"]) == ("R1", 0.0, 8.0, None)
    assert cut[0]["needed_s"] == pytest.approx(5.94, abs=0.01) and cut[0]["available_s"] == 8.0
    (listed,) = plan.stats["approaches"]
    assert listed["t1_s"] * 1.0 >= (1 + MARGIN) * listed["needed_s"]
    assert Plan.from_dict(plan.to_dict()).stats["approaches_cut"] == cut


def test_with_no_repairs_the_planner_refuses_and_says_why(round_to_push):
    scenario, _, _ = round_to_push
    with pytest.raises(UnflyableHandoverError) as info:
        plan_spatially_robust(scenario, PlannerConfig(handover=HandoverConfig(repairs=0)))
    err = info.value
    assert isinstance(err, InfeasiblePlanError)
    assert "has an approach its robot cannot fly: R1 round O1 to its first impact at 8.00 s from its start: " \
           "needs at least 5.94 s (8.91 s with the 50 % margin), has 8.00 s" in str(err)
    assert [(a.robot, a.t1_s) for a in err.handovers] == [("R1", 8.0)]
    assert err.plan is not None and err.plan.impacts[0].time_s == 8.0


def test_a_plan_without_the_robots_curve_is_refused_by_name(two_objects):
    from planners.errors import PlanCheckError

    scenario = starting(two_objects, R1=(2.3, 1.5), R2=(0.5, 1.5), O1=(1.5, 1.5))
    first = impact(4.0, "R2", "O1", (1.5, 1.5), (0, 0), (0.1, 0))
    second = impact(10.0, "R1", "O1", (2.1, 1.5), (0.1, 0), (0.15, 0))
    with pytest.raises(PlanCheckError, match="no curve of R1: .* when R2 hits O1 at 4 s"):
        approaches(Plan("two_objects", "sr", 0.0, {}, [first, second]), scenario)


def test_every_committed_plan_leaves_its_robots_time_to_get_round():
    """The plans the tests and benchmarks fly (tests/data/plans/shipped/, results/impact_robust/plans/,
    results/robustness/plans/) pass the check: corridor's and relay's IR plans were planned again with it
    (docs/planner_design.md#hand-overs). Their ways round now have 1.6 (relay's R2) to 4.3 (obstacle_avoidance's
    R2) times their least time."""
    import json

    root = DATA.parents[1]
    folders = [DATA / "plans" / "shipped", root / "results" / "impact_robust" / "plans",
               root / "results" / "robustness" / "plans"]
    paths = [p for folder in folders for p in sorted(folder.rglob("*.json"))]
    assert len(paths) >= 50
    ratios = {}
    for path in paths:
        plan = Plan.from_dict(json.loads(path.read_text()))
        found = approaches(plan, load_scenario(plan.scenario))
        assert all(a.flyable(MARGIN) for a in found), (path, [a.describe(MARGIN) for a in found])
        ratios.update({(plan.scenario, plan.planner, a.robot): a.available_s / a.needed_s for a in found})
    assert ratios[("relay", "ir", "R2")] == pytest.approx(1.58, abs=0.01)
    assert ratios[("corridor", "ir", "R2")] == pytest.approx(1.86, abs=0.01)
    assert max(ratios.values()) == pytest.approx(4.33, abs=0.01)


def test_the_cut_excludes_exactly_that_first_impact_with_that_flight_of_the_object():
    """``cut_approach``'s row on a bare model of impact binaries z[R, O, k] (knots 2 s apart): from the start,
    R1's first impact on O1 at knot 3 is cut unless R1 hits something or O1 is hit before; after R2's impact
    on O1 at knot 1, R1's at knot 4 is cut unless R1 hits something before or O1 is hit in between."""
    from planners.offline.milp.impacts import ImpactVars
    from planners.offline.milp.model import LinExpr, Model
    from planners.offline.stages import HANDOVER_GROUP, StagedModel, cut_approach
    from planners.plan.approach import Approach

    def model_with(cut):
        m = Model("cuts")
        z = {(r, o, k): m.add_binary(f"z_{r}_{o}_{k}") for r in ("R1", "R2") for o in ("O1", "O2") for k in range(6)}
        staged = StagedModel(m, LinExpr(), "delta", LinExpr(), LinExpr(), 1.0, [], impacts=ImpactVars(z), grid_dt_s=2.0)
        cut_approach(staged, cut)
        assert m.row_groups == [HANDOVER_GROUP]
        names = list(z)
        return lambda *hits: not m.check(np.array([1.0 if key in hits else 0.0 for key in names]))

    allowed = model_with(Approach("R1", "O1", 0.0, 6.0, 10.0))
    assert not allowed(("R1", "O1", 3))
    assert allowed(("R1", "O2", 1), ("R1", "O1", 3)) and allowed(("R2", "O1", 2), ("R1", "O1", 3))
    assert allowed(("R1", "O1", 4))  # another knot
    assert not allowed(("R2", "O1", 4), ("R1", "O1", 3))  # what comes after does not change the way there
    allowed = model_with(Approach("R1", "O1", 2.0, 8.0, 10.0, by="R2"))
    assert not allowed(("R2", "O1", 1), ("R1", "O1", 4))
    assert allowed(("R1", "O1", 4)) and allowed(("R2", "O1", 0), ("R1", "O1", 4))  # another flight of O1
    assert allowed(("R2", "O1", 1), ("R2", "O1", 3), ("R1", "O1", 4))  # hit again in between
    assert allowed(("R2", "O1", 1), ("R1", "O2", 0), ("R1", "O1", 4))  # not R1's first impact
