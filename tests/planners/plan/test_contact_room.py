"""Contact room (planners/plan/contact_room.py): where a disc robot must be at a plan's impact, and whether it
fits there. The planner's rows that keep it: tests/planners/offline/test_point_contact_room.py."""

from __future__ import annotations

import json

import numpy as np
import pytest

from impact_env.transport.scenario import load_scenario
from planners.plan import Plan, PlannedImpact
from planners.plan.contact_room import ROOM_TOLERANCE_M, contact_centre, contacts, contacts_without_room, room_m
from tests.paths import DATA


def impact(t, robot, obj, position, v_obj_before, v_obj_after, e=0.6):
    """A planned impact of equal masses (Eq. 5): the robot's velocities from the object's change."""
    vo0, vo1 = np.asarray(v_obj_before, float), np.asarray(v_obj_after, float)
    vr0 = vo0 + (vo1 - vo0) / ((1 + e) / 2)
    return PlannedImpact(t, robot, obj, tuple(position), tuple(vo0), tuple(vo1), tuple(vr0), tuple(vo0 + vr0 - vo1))


@pytest.fixture(scope="module")
def obstacle_avoidance():
    """World [0, 10]^2, obstacle box [3, 7] x [2, 4]; robots and objects of 0.2 m."""
    return load_scenario("obstacle_avoidance")


def test_the_centre_is_one_robot_and_object_radius_behind_the_object_against_the_push(obstacle_avoidance):
    centre = contact_centre(obstacle_avoidance, "R1", "O1", (5.0, 8.0), (0.0, -1.0))
    assert centre == pytest.approx([5.0, 8.4])
    centre = contact_centre(obstacle_avoidance, "R1", "O1", (5.0, 8.0), (0.6, 0.8))
    assert centre == pytest.approx([5.0 - 0.24, 8.0 - 0.32])


def test_the_room_is_the_distance_inside_the_world_shrunk_by_the_robot(obstacle_avoidance):
    # nearest the top wall at 10: 10 - 0.2 - 9.5
    assert room_m(obstacle_avoidance, "R1", (5.0, 9.5)) == pytest.approx(0.3)
    # beyond the left wall: 0.1 - 0 - 0.2
    assert room_m(obstacle_avoidance, "R1", (0.1, 8.0)) == pytest.approx(-0.1)
    # 1.0 below the top wall shrunk by 0.2, 4.6 above the obstacle grown by it: the nearer counts
    assert room_m(obstacle_avoidance, "R1", (5.0, 8.8)) == pytest.approx(1.0)


def test_the_room_outside_an_obstacle_is_its_bounding_box_grown_by_the_robot(obstacle_avoidance):
    assert room_m(obstacle_avoidance, "R1", (5.0, 4.5)) == pytest.approx(0.3)  # above: 4.5 - 4 - 0.2
    assert room_m(obstacle_avoidance, "R1", (2.9, 3.0)) == pytest.approx(-0.1)  # left side, 0.1 from it
    assert room_m(obstacle_avoidance, "R1", (5.0, 3.0)) == pytest.approx(-1.2)  # inside: 1 from its top, +0.2
    # beside a corner the grown box has square corners, as the impact-robust planner's rows (conservative)
    assert room_m(obstacle_avoidance, "R1", (7.15, 4.15)) == pytest.approx(-0.05)


def test_a_plans_contacts_and_those_without_room(obstacle_avoidance):
    """Pushed down at (5, 9.7): the disc's centre at y 10.1, 0.3 beyond the top wall shrunk by 0.2. Pushed
    right at (5, 5): room. An impact that does not change the object's velocity leaves the side open."""
    pushes = [impact(2.0, "R1", "O1", (5.0, 9.7), (0, 0), (0, -0.1)),
              impact(4.0, "R2", "O1", (5.0, 5.0), (0, -0.1), (0.1, -0.1)),
              impact(6.0, "R1", "O1", (5.2, 4.8), (0.1, -0.1), (0.1, -0.1))]
    plan = Plan("obstacle_avoidance", "sr", 0.0, {}, pushes)
    found = contacts(plan, obstacle_avoidance)
    assert [(c.robot, c.time_s) for c in found] == [("R1", 2.0), ("R2", 4.0)]
    assert found[0].centre == pytest.approx((5.0, 10.1)) and found[0].room_m == pytest.approx(-0.3)
    assert found[1].centre == pytest.approx((4.6, 5.0)) and found[1].room_m == pytest.approx(0.8)
    (bad,) = contacts_without_room(plan, obstacle_avoidance)
    assert bad == found[0] and not bad.flyable() and found[1].flyable()
    assert bad.describe() == ("R1 on O1 at 2.00 s: its centre would be at (5.000, 10.100) m, 0.300 m beyond a wall "
                              "or into an obstacle")
    assert bad.to_dict() == {"robot": "R1", "object": "O1", "time_s": 2.0, "centre_m": pytest.approx([5.0, 10.1]),
                             "room_m": pytest.approx(-0.3)}


def test_the_tolerance_lets_a_contact_graze_the_wall(obstacle_avoidance):
    """Pushed down at y 9.4 + x, the disc's centre is x beyond the top wall shrunk by 0.2."""
    def pushed_down_at(y):
        return Plan("obstacle_avoidance", "sr", 0.0, {}, [impact(2.0, "R1", "O1", (5.0, y), (0, 0), (0, -0.1))])

    grazing = pushed_down_at(9.4 + 0.5 * ROOM_TOLERANCE_M)
    (c,) = contacts(grazing, obstacle_avoidance)
    assert c.room_m == pytest.approx(-0.5 * ROOM_TOLERANCE_M) and c.flyable()
    assert contacts_without_room(grazing, obstacle_avoidance) == []
    assert len(contacts_without_room(pushed_down_at(9.4 + 2 * ROOM_TOLERANCE_M), obstacle_avoidance)) == 1


def test_every_committed_plan_leaves_its_robots_room_behind_their_contacts():
    """The plans the tests and benchmarks fly (tests/data/plans/shipped/, results/impact_robust/plans/,
    results/robustness/plans/) pass the check; the least room is the impact-robust plans' (their rows ask for
    it at every state of the box, so the nominal contact may sit right at the wall)."""
    root = DATA.parents[1]
    folders = [DATA / "plans" / "shipped", root / "results" / "impact_robust" / "plans",
               root / "results" / "robustness" / "plans"]
    paths = [p for folder in folders for p in sorted(folder.rglob("*.json"))]
    assert len(paths) >= 50
    rooms = []
    for path in paths:
        plan = Plan.from_dict(json.loads(path.read_text()))
        scenario = load_scenario(plan.scenario)
        assert contacts_without_room(plan, scenario) == [], (path, [c.describe() for c in
                                                                    contacts_without_room(plan, scenario)])
        rooms += [c.room_m for c in contacts(plan, scenario)]
    assert len(rooms) >= 100 and min(rooms) >= -ROOM_TOLERANCE_M
