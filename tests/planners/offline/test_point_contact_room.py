"""The spatially robust planner's contact-room rows (``PlannerConfig.contact_cones``,
planners/offline/milp/contact_room.py): with them, no contact of the plan asks the disc robot to stand beyond a
wall; without them (the default, the paper's point robots) the planner does on tests/data/push_off_ceiling.toml."""

from __future__ import annotations

import pytest

from impact_env.transport.scenario import load_scenario
from planners.errors import PlannerError
from planners.offline.config import IRPlannerConfig, PlannerConfig
from planners.offline.spatially_robust import build_model, plan_spatially_robust
from planners.plan.checks import check_plan
from planners.plan.contact_room import contacts, contacts_without_room
from tests.paths import DATA


@pytest.fixture(scope="module")
def push_off_ceiling():
    """O1 (r 0.2) drifts down at 0.02 m/s from y 2.6 under the ceiling at 3.0; R1 (r 0.2) must push it down into
    the goal [1, 2] in y. Planned without and with the rows."""
    scenario = load_scenario(DATA / "push_off_ceiling.toml")
    return scenario, plan_spatially_robust(scenario), plan_spatially_robust(scenario, PlannerConfig(contact_cones=8))


def test_point_robots_push_from_beyond_the_ceiling(push_off_ceiling):
    """At 8 s O1 is at y 2.6 - 8 x 0.02 = 2.44: pushed straight down, the disc's centre is at 2.84, 0.04 m above
    the highest it can be (3.0 - 0.2)."""
    scenario, plain, _ = push_off_ceiling
    (c,) = contacts_without_room(plain, scenario)
    assert (c.robot, c.object, c.time_s) == ("R1", "O1", 8.0)
    assert c.centre == pytest.approx((2.5, 2.84), abs=1e-6) and c.room_m == pytest.approx(-0.04, abs=1e-6)


def test_with_the_rows_every_contact_has_room(push_off_ceiling):
    """Every contact of the plan with the rows has room (to the solver's tolerance), the plan passes the plan
    checks, and the rows cost robustness (the plain plan's push is no longer allowed), never add it."""
    scenario, plain, room = push_off_ceiling
    check_plan(room, scenario)
    found = contacts(room, scenario)
    assert found and min(c.room_m for c in found) >= -1e-6
    assert 0 < room.robustness <= plain.robustness + 1e-6


def test_the_rows_are_one_cone_binary_per_mode_per_robot_object_and_knot():
    """8 cones plus "any side" per (robot, object, interior knot), plus 4 side binaries per obstacle: the model
    grows by exactly that many binaries (push_off_ceiling: 1 robot, 1 object, 9 interior knots, no obstacle)."""
    scenario = load_scenario(DATA / "push_off_ceiling.toml")
    plain = build_model(scenario, PlannerConfig()).model
    room = build_model(scenario, PlannerConfig(contact_cones=8)).model
    assert room.n_binaries - plain.n_binaries == 9 * 9
    four = build_model(scenario, PlannerConfig(contact_cones=4)).model
    assert four.n_binaries - plain.n_binaries == 9 * 5


@pytest.mark.parametrize("cones", [3, 0, -8, 2.5, True, "8"])
def test_a_bad_cone_count_is_a_typed_error(cones):
    with pytest.raises(PlannerError, match="contact_cones"):
        PlannerConfig(contact_cones=cones)


def test_the_impact_robust_planner_keeps_its_default_of_eight_cones():
    assert PlannerConfig().contact_cones is None and IRPlannerConfig().contact_cones == 8
