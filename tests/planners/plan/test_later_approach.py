"""Later approaches: a robot's way from its impact on one object to the far side of another
(``approaches(..., later=True)``, ``HandoverConfig.later_approaches``, ``MissionConfig.later_approaches``), and
the tangent rows that take a replanned approach round the object (``WayRound``)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from impact_env.transport.scenario import load_scenario
from planners.offline.config import HandoverConfig
from planners.online.mission import MissionConfig
from planners.online.replanner import replan_around_impact, replan_segment, respects
from planners.online.segment_qp import SegmentLimits, WayRound
from planners.plan import Plan
from planners.plan.approach import approaches, unflyable_approaches
from planners.plan.handover import least_time_1d_s
from tests.planners.plan.test_approach import ACCEL, MARGIN, impact, starting, still


@pytest.fixture(scope="module")
def two_objects():
    return load_scenario("two_objects")


def one_robot_two_pushes(scenario, second_at_s: float):
    """R1 starts left of O2 and pushes it right at 4 s; then it must push O1, 1 m to the right of where O2 was,
    to the left at ``second_at_s``: its contact is on O1's right-hand side, beyond the object from where R1 is."""
    scenario = starting(scenario, R1=(0.5, 1.5), O2=(1.0, 1.5), O1=(2.0, 1.5))
    first = impact(4.0, "R1", "O2", (1.0, 1.5), (0, 0), (0.05, 0))
    second = impact(second_at_s, "R1", "O1", (2.0, 1.5), (0, 0), (-0.05, 0))
    plan = Plan("two_objects", "sr", 0.0, {"R1": still("R1", (1.0, 1.5)),
                                           "O1": still("O1", (2.0, 1.5)), "O2": still("O2", (1.0, 1.5))},
                [first, second])
    return scenario, plan, first, second


def test_a_later_contact_beyond_the_object_is_an_approach_only_when_asked(two_objects):
    """The first push needs no way round (R1 comes from the left), so the first-impact test finds nothing. The
    second starts where the first left R1: 1 m left of O1 at +0.0125 m/s (the push's rebound, e = 0.6), to 0.4 m
    right of it at -0.0625 m/s. Getting round the side is shorter than the way along x, so the least time is the
    1-D one along x, in closed form."""
    scenario, plan, first, second = one_robot_two_pushes(two_objects, 16.0)
    assert approaches(plan, scenario) == []
    (a,) = approaches(plan, scenario, later=True)
    assert (a.robot, a.object, a.t0_s, a.t1_s, a.by, a.after) == ("R1", "O1", 4.0, 16.0, None, first)
    assert a.impact == second
    assert a.needed_s == pytest.approx(least_time_1d_s(1.4, 0.0125, -0.0625, ACCEL, -0.3, 0.3), rel=1e-9)
    assert a.needed_s == pytest.approx(6.81, abs=0.01) and a.flyable(MARGIN)  # 12 s >= 1.5 x 6.81 s
    assert "R1 round O1 to its impact at 16.00 s from its impact on O2 at 4.00 s" in a.describe(MARGIN)
    assert a.to_dict()["after"] == {"object": "O2", "time_s": 4.0}
    # with the second push 6 s after the first there is not the time (10.2 s with the margin)
    scenario, plan, _, _ = one_robot_two_pushes(two_objects, 10.0)
    assert [u.t1_s for u in unflyable_approaches(plan, scenario, MARGIN, later=True)] == [10.0]
    assert unflyable_approaches(plan, scenario, MARGIN) == []


def test_a_later_approach_is_tested_with_the_planned_margin_not_the_observed_one():
    """The mission layer gives re-plans a smaller margin for ways round from the observed start; a later approach
    starts at a planned impact, so it keeps the planner's margin."""
    config = HandoverConfig(start_approach_margin=0.25)
    scenario = load_scenario("two_objects")
    _, plan, _, _ = one_robot_two_pushes(scenario, 16.0)
    (a,) = approaches(plan, starting(scenario, R1=(0.5, 1.5), O2=(1.0, 1.5), O1=(2.0, 1.5)), later=True)
    assert config.margin_of(a) == 0.5
    assert config.margin_of(dataclasses.replace(a, after=None)) == 0.25


def test_a_push_on_the_same_object_again_is_a_hand_over_not_an_approach(two_objects):
    scenario = starting(two_objects, R1=(0.5, 1.5), O1=(2.0, 1.5))
    first = impact(4.0, "R1", "O1", (2.0, 1.5), (0, 0), (0.05, 0))
    stop = impact(12.0, "R1", "O1", (2.4, 1.5), (0.05, 0), (0.0, 0))
    plan = Plan("two_objects", "sr", 0.0, {"R1": still("R1", (2.0, 1.5)), "O1": still("O1", (2.0, 1.5))},
                [first, stop])
    assert approaches(plan, scenario, later=True) == []


def test_the_cut_of_a_later_approach_excludes_that_pair_of_impacts():
    """``cut_approach`` on a bare model of impact binaries (knots 2 s apart): R1's impact on O1 at knot 4 after its
    impact on O2 at knot 2 is cut, unless R1 hits something or O1 is hit in between."""
    from planners.offline.milp.impacts import ImpactVars
    from planners.offline.milp.model import LinExpr, Model
    from planners.offline.stages import StagedModel, cut_approach
    from planners.plan.approach import Approach

    m = Model("cuts")
    z = {(r, o, k): m.add_binary(f"z_{r}_{o}_{k}") for r in ("R1", "R2") for o in ("O1", "O2") for k in range(6)}
    staged = StagedModel(m, LinExpr(), "rho", LinExpr(), LinExpr(), 1.0, [], impacts=ImpactVars(z), grid_dt_s=2.0)
    after = impact(4.0, "R1", "O2", (1.0, 1.5), (0, 0), (0.05, 0))
    cut_approach(staged, Approach("R1", "O1", 4.0, 8.0, 10.0, after=after))
    names = list(z)

    def allowed(*hits):
        return not m.check(np.array([1.0 if key in hits else 0.0 for key in names]))

    assert not allowed(("R1", "O2", 2), ("R1", "O1", 4))
    assert allowed(("R1", "O1", 4)) and allowed(("R1", "O2", 1), ("R1", "O1", 4))  # another way there
    assert allowed(("R1", "O2", 2), ("R1", "O2", 3), ("R1", "O1", 4))  # R1 hits something in between
    assert allowed(("R1", "O2", 2), ("R2", "O1", 3), ("R1", "O1", 4))  # O1 is hit in between
    assert not allowed(("R1", "O2", 2), ("R2", "O1", 1), ("R1", "O1", 4))  # before the way starts: no matter


def test_the_mission_passes_later_approaches_to_its_re_plans():
    assert MissionConfig().later_approaches is False
    with pytest.raises(Exception, match="later_approaches"):
        MissionConfig(later_approaches="yes")
    with pytest.raises(Exception, match="later_approaches"):
        HandoverConfig(later_approaches=1)


# ------------------------------------------------------------------------------------ the replanned segment
def way_round_case(duration_s: float):
    """A robot 1 m left of an object at rest (radius sum 0.4 m), to touch it from the right at 0.06 m/s."""
    centre = np.array([2.0, 1.5])
    robot = np.array([1.0, 1.5])
    contact = centre + np.array([0.4, 0.0])

    def at(times):
        return np.tile(centre, (len(np.atleast_1d(times)), 1))

    way = WayRound.between(robot, contact, at, 0.0, duration_s, 0.4)
    return robot, contact, centre, way


def test_the_way_round_takes_the_short_turn_and_its_rows_are_tangents():
    robot, contact, centre, way = way_round_case(20.0)
    assert way is not None
    assert WayRound.between(contact + [0.5, 0.0], contact, lambda t: np.tile(centre, (len(t), 1)), 0.0, 20.0,
                            0.4) is None  # already on the right: the straight way misses the disc
    assert abs(way.bearing1 - way.bearing0) == pytest.approx(math.pi)
    rows = way.rows(0.0, 20.0)
    assert len(rows) == 8
    phases = [phase for phase, _, _ in rows]
    assert phases == sorted(phases) and 0.0 < phases[0] and phases[-1] < 1.0  # the ends are fixed states
    for phase, normal, offset in rows:
        bearing = way.bearing0 + phase * (way.bearing1 - way.bearing0)  # turning in step with the phase
        assert normal == pytest.approx([math.cos(bearing), math.sin(bearing)])
        assert offset == pytest.approx(normal @ centre + 0.4)  # the tangent at that bearing


def test_a_replanned_approach_with_the_time_goes_round_and_without_it_falls_back():
    """With 20 s the bounded QP finds a segment that stays outside the disc at every sample and keeps the rows; the
    straight Hermite segment cuts through the object. With 3 s no segment can get round within the thrust, and
    the replanner gives the rows up (the MPC's keep-off is left), as it gives up the other limits."""
    robot, contact, centre, way = way_round_case(20.0)
    v_end = np.array([-0.06, 0.0])
    accel = (0.8 * ACCEL, 0.8 * ACCEL)
    straight = replan_segment(robot, np.zeros(2), contact, v_end, 0.0, 20.0, (0.3, 0.3), None, accel)
    inside = np.hypot(*(straight.position(np.linspace(0, 20, 201)) - centre).T)
    assert inside.min() < 0.4
    limits = SegmentLimits(way_round=way)
    round_ = replan_segment(robot, np.zeros(2), contact, v_end, 0.0, 20.0, (0.3, 0.3), limits, accel)
    assert respects(round_, (0.3, 0.3), limits, tol=1e-6)
    distance = np.hypot(*(round_.position(np.linspace(0, 20, 201)[1:-1]) - centre).T)
    assert distance.min() > 0.4 - 0.02  # the rows hold at 8 samples; between them it may graze
    assert np.allclose(round_.position(20.0), contact) and np.allclose(round_.velocity(20.0), v_end, atol=1e-9)
    _, _, _, short = way_round_case(3.0)
    fallback = replan_segment(robot, np.zeros(2), contact, v_end, 0.0, 3.0, (0.3, 0.3),
                              SegmentLimits(way_round=short), accel)
    assert not respects(fallback, (0.3, 0.3), SegmentLimits(way_round=short), tol=1e-6)


def test_only_the_pre_impact_segment_gets_the_way_round():
    from planners.online.impact_model import ContactPlan

    robot, contact, centre, way = way_round_case(20.0)
    plan = ContactPlan(normal=np.array([-1.0, 0.0]), robot_position=contact,
                       robot_velocity_before=np.array([-0.06, 0.0]), robot_velocity_after=np.array([0.0, 0.0]),
                       object_velocity_after=np.array([-0.05, 0.0]))
    pre, post = replan_around_impact(0.0, robot, np.zeros(2), 20.0, plan, 25.0, contact + [0.5, 0.0],
                                     np.zeros(2), (0.3, 0.3), None, (0.13, 0.13), way_round=way)
    assert respects(pre, (0.3, 0.3), SegmentLimits(way_round=way), tol=1e-6)
    # the post-impact segment starts in contact with the object: with the rows it could not start
    assert post.t0_s == 20.0 and np.allclose(post.position(20.0), contact)


# ------------------------------------------------------------------------------------ the mission's re-plans
def test_a_re_plan_with_a_way_round_it_cannot_fly_is_repaired_or_refused():
    """one_robot_two_objects seed 19's re-plan at 20.2 s (tests/planners/online/test_mission_finer_grid.py), found
    on the finer grid: without the option it is accepted, and asks R1 to push O2 at 27.66 s and then O1 from its far
    side at 37.61 s, 9.95 s later, where getting round takes at least 9.20 s. With ``later_approaches`` the
    planner's repair cuts that pair of impacts, finds no other plan within its repairs, and the mission keeps its
    plan (the re-plan is refused as unflyable)."""
    from tests.planners.online.test_mission_finer_grid import replan

    scenario = load_scenario("one_robot_two_objects")
    out, record = replan(finer_grid_retry=True)
    assert out is not None and record.status.startswith("accepted")
    bad = [a for a in approaches(out[0], scenario, later=True) if not a.flyable(MARGIN)]
    assert [(a.robot, a.object, a.after.object, round(a.t1_s, 2), round(a.needed_s, 2)) for a in bad] == \
        [("R1", "O1", "O2", 37.61, 9.2)]
    out, record = replan(finer_grid_retry=True, later_approaches=True)
    assert out is None and record.status == "kept: UnflyableHandoverError"


def test_a_way_round_the_box_does_not_allow_is_given_up_before_the_box(monkeypatch):
    """The short way round passes above the object (y up to 1.9 m); a world box that stops the robot's centre at
    y = 1.8 m leaves no such segment. The replanner then tries the box without the way round, the segment it
    flew before the option, before it drops every limit (the QPs it solves, in order: recorded)."""
    import planners.online.replanner as replanner

    robot, contact, centre, way = way_round_case(20.0)
    assert math.sin(0.5 * (way.bearing0 + way.bearing1)) > 0.99  # halfway round: straight above the object
    asked = []
    solve = replanner.bounded_segment

    def recording(*args, limits=None, **kwargs):
        asked.append(limits)
        return solve(*args, limits=limits, **kwargs)

    monkeypatch.setattr(replanner, "bounded_segment", recording)
    box = SegmentLimits(box=(0.0, 4.0, 1.0, 1.8))
    both = SegmentLimits(box=box.box, way_round=way)
    segment = replan_segment(robot, np.zeros(2), contact, np.array([-0.06, 0.0]), 0.0, 20.0, (0.3, 0.3), both,
                             (0.8 * ACCEL, 0.8 * ACCEL))
    assert [(a.box, a.way_round is not None) for a in asked] == [(box.box, True), (box.box, False)]
    assert respects(segment, (0.3, 0.3), box, tol=1e-6) and not respects(segment, (0.3, 0.3), both, tol=1e-6)
