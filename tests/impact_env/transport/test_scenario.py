"""Scenario loading: shipped files match the paper's numbers; every invalid field gives a ScenarioError
that names its path."""

from __future__ import annotations

import pytest

from impact_env.errors import ScenarioError
from impact_env.transport.scenario import load_scenario, scenario_from_dict, scenario_names
from tests.helpers import DELETE, modified, two_body_dict


def test_shipped_scenarios_are_listed_and_load():
    assert scenario_names() == ["corridor", "four_robots", "held_drift", "long_throw_trim", "narrow_gap",
                                "obstacle_avoidance", "one_robot_two_objects", "ping_pong_stop", "relay",
                                "throw_and_catch_exp", "timed_visits", "two_objects", "wall_start"]
    for name in scenario_names():
        sc = load_scenario(name)
        assert sc.name == name
        assert sc.formula.horizon_s <= sc.tf_s


def test_corridor_numbers_from_the_paper():
    sc = load_scenario("corridor")
    assert sc.world_box == (-1.0, 3.0, 0.0, 10.0)
    assert sc.restitution == 0.75 and sc.tf_s == 100.0
    assert [r.name for r in sc.robots] == ["R1", "R2"] and [o.name for o in sc.objects] == ["O1"]
    assert sc.body("R1").position_m == (1.0, 1.0) and sc.body("R2").position_m == (1.0, 9.0)
    assert sc.body("O1").position_m == (1.0, 2.0)
    assert sc.region_map()["goal"].bounds == (0.25, 1.75, 7.25, 8.75)
    assert sc.region_map()["W1"].bounds == (-1.0, 0.0, 0.0, 10.0)
    assert sc.body("R1").mass_kg == 16.8 and sc.body("R1").radius_m == 0.2
    assert sc.body("R1").thrust_limit_N == (2.8, 2.8)
    assert sc.bezier_segments == {"R1": 4, "R2": 3, "O1": 6}
    assert sc.formula.bodies() == {"R1", "R2", "O1"}


def test_lab_and_obstacle_numbers():
    lab = load_scenario("throw_and_catch_exp")
    assert lab.restitution == 0.47 and lab.tf_s == 20.0 and lab.world_box == (0.0, 4.0, -1.5, 1.5)
    obs = load_scenario("obstacle_avoidance")
    assert obs.tf_s == 150.0 and obs.region_map()["obs"].bounds == (3.0, 7.0, 2.0, 4.0)
    assert obs.body("O1").final_position_m == (5.0, 1.0)


def test_user_file_by_path(tmp_path):
    text = (load_scenario("corridor").source and
            __import__("importlib.resources").resources.files("impact_env.transport.scenarios")
            .joinpath("corridor.toml").read_text())
    path = tmp_path / "mine.toml"
    path.write_text(text.replace('name = "corridor"', 'name = "mine"'))
    assert load_scenario(path).name == "mine"
    assert load_scenario(str(path)).name == "mine"


@pytest.mark.parametrize("path,value,message", [
    ("robots.0.radius_m", -0.2, "robots[0].radius_m must be > 0, got -0.2"),
    ("objects.0.mass_kg", 0, "objects[0].mass_kg must be > 0"),
    ("restitution", 1.5, "restitution must be in [0, 1]"),
    ("restitution", "high", "restitution must be a finite number"),
    ("robots.0.colour", "red", "robots[0].colour: unknown key"),
    ("wheels", 4, "wheels: unknown key"),
    ("robots.0.position_m", [1.0], "robots[0].position_m must be a list of 2 numbers"),
    ("robots.0.position_m", [-5.0, 5.0], "outside the world box"),
    ("objects.0.position_m", [2.1, 5.0], "overlap"),
    ("world.box", [1, 0, 0, 1], "world.box must have xmin < xmax"),
    ("substeps", 0, "substeps must be >= 1"),
    ("robots.0.thrust_limit_N", [2.8, -1], "robots[0].thrust_limit_N[1] must be > 0"),
    ("task", "F[0,10] in(O9, goal)", "task names body 'O9'"),
    ("task", "F[0,10] in(O1, moon)", "task names region 'moon'"),
    ("task", "F[0,10] in(O1, goal", "task:"),
    ("task", "in(O1, goal)", "no temporal operator"),
    ("task", "F[0,50] in(O1, goal)", "exceeds tf_s"),
    ("robots.0.thrust_limit_N", DELETE, "robots[0].thrust_limit_N is required"),
    ("regions.0.box", DELETE, "regions[0] needs exactly one of"),
])
def test_invalid_fields_name_their_path(path, value, message):
    with pytest.raises(ScenarioError, match=_escape(message)):
        scenario_from_dict(modified(two_body_dict(), path, value))


def _escape(text: str) -> str:
    import re

    return re.escape(text)


def test_nonconvex_polygon_and_bad_segments():
    data = two_body_dict()
    data["obstacles"] = [{"name": "L", "polygon": [[5, 1], [7, 1], [7, 3], [6, 2], [5, 3]]}]
    with pytest.raises(ScenarioError, match="not convex"):
        scenario_from_dict(data)
    data = two_body_dict()
    data["planner"] = {"bezier_segments": {"R7": 3}}
    with pytest.raises(ScenarioError, match="planner.bezier_segments.R7: no body named 'R7'"):
        scenario_from_dict(data)


def test_wrench_limits_are_a_robots_and_an_object_has_none():
    sc = load_scenario("corridor")
    robot = sc.body("R1")
    assert robot.wrench_limits == (*robot.thrust_limit_N, robot.torque_limit_Nm)
    with pytest.raises(ScenarioError, match="body 'O1' is an object: it has no thrust_limit_N"):
        _ = sc.body("O1").wrench_limits


def test_substep_check_suggests_a_number():
    data = two_body_dict(substeps=1)
    data["robots"][0]["velocity_bound_mps"] = [2.0, 2.0]
    with pytest.raises(ScenarioError, match=r"use substeps >= \d+"):
        scenario_from_dict(data)


def test_final_box_table():
    data = two_body_dict()
    sc = scenario_from_dict({**data, "final_box": {"O1": {"position_m": 0.5, "velocity_mps": [0.05, 0.1]}}})
    box = sc.final_box("O1")
    assert box.position_m == (0.5, 0.5) and box.velocity_mps == (0.05, 0.1)
    assert scenario_from_dict(data).final_box("O1") is None
    assert load_scenario("throw_and_catch_exp").final_box("O1").position_m == (0.4, 0.4)
    assert load_scenario("corridor").final_box("O1").velocity_mps == (0.05, 0.05)


@pytest.mark.parametrize("table, message", [
    ({"R1": {"position_m": 0.5, "velocity_mps": 0.05}}, "final_box.R1: no object named 'R1'"),
    ({"O1": {"position_m": 0.5}}, "final_box.O1.velocity_mps is required"),
    ({"O1": {"position_m": -0.5, "velocity_mps": 0.05}}, "final_box.O1.position_m must be > 0"),
    ({"O1": {"position_m": 0.5, "velocity_mps": [0.05, 0.0]}}, r"final_box.O1.velocity_mps\[1\] must be > 0"),
    ({"O1": {"position_m": [0.5], "velocity_mps": 0.05}}, "final_box.O1.position_m must be a list of 2 numbers"),
    ({"O1": {"position_m": 0.5, "velocity_mps": 0.05, "speed": 1}}, "final_box.O1.speed: unknown key"),
    ({"O1": 0.5}, "final_box.O1 must be a table"),
])
def test_bad_final_box_names_the_field(table, message):
    with pytest.raises(ScenarioError, match=message):
        scenario_from_dict({**two_body_dict(), "final_box": table})


def test_copy_intervals_hint_is_checked():
    data = {**two_body_dict(), "planner": {"intervals": 10, "copy_intervals": 3}}
    assert scenario_from_dict(data).planner_copy_intervals == 3
    with pytest.raises(ScenarioError, match=r"planner.copy_intervals must be in 1..5"):
        scenario_from_dict({**data, "planner": {"intervals": 10, "copy_intervals": 6}})
