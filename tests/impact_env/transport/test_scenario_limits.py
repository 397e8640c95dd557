"""Scenario files that used to crash or be accepted and then break (issue 11): each is now a typed error
naming the field, or, where the input is legitimate, works."""

from __future__ import annotations

import copy
import math
import pickle
import sys
from importlib import resources

import numpy as np
import pytest

from impact_env.envs import TransportEnv
from impact_env.errors import ScenarioError
from impact_env.geometry import ConvexPolygon
from impact_env.transport.scenario import load_scenario, scenario_from_dict

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

CORRIDOR_TEXT = resources.files("impact_env.transport.scenarios").joinpath("corridor.toml").read_text()
CORRIDOR = tomllib.loads(CORRIDOR_TEXT)
GOAL_CORNERS = [[0.25, 7.25], [1.75, 7.25], [1.75, 8.75], [0.25, 8.75]]


def corridor(**changes) -> dict:
    data = copy.deepcopy(CORRIDOR)
    for path, value in changes.items():
        node = data
        keys = [int(k) if k.isdigit() else k for k in path.split("__")]
        for k in keys[:-1]:
            node = node[k]
        node[keys[-1]] = value
    return data


def with_goal_polygon(vertices) -> dict:
    data = corridor()
    del data["regions"][0]["box"]
    data["regions"][0]["polygon"] = vertices
    return data


def steps_finite_and_inside(scenario, actions, steps: int = 30) -> list[float]:
    env = TransportEnv(scenario)
    env.reset(seed=0)
    rewards = []
    xmin, xmax, ymin, ymax = scenario.world_box
    for _ in range(steps):
        obs, reward, terminated, _, info = env.step(actions)
        rewards.append(reward)
        assert np.all(np.isfinite(obs)) and math.isfinite(reward) and math.isfinite(info["robustness"])
        for x, y, *_ in env.core._state:
            assert xmin <= x <= xmax and ymin <= y <= ymax
        if terminated:
            break
    return rewards


def test_latin1_byte_is_a_scenario_error_naming_line_and_file(tmp_path):
    path = tmp_path / "latin1.toml"
    path.write_bytes(CORRIDOR_TEXT.replace("Throw and catch", "Throw and catch \xe9").encode("latin-1"))
    with pytest.raises(ScenarioError, match=r"latin1\.toml: not UTF-8 text \(byte 0xe9 at line 4"):
        load_scenario(path)


@pytest.mark.parametrize("task", [
    "(" * 200 + "F[0,10] in(O1, goal)" + ")" * 200,
    "F[0,10] " + "!" * 500 + "in(O1, goal)",
    "F[0,10] " * 300 + "in(O1, goal)",
])
def test_deep_nesting_is_a_clear_limit(task):
    with pytest.raises(ScenarioError, match=f"nests deeper than {100} levels"):
        scenario_from_dict(corridor(task=task))


def test_nesting_up_to_the_limit_parses_and_evaluates():
    scenario = scenario_from_dict(corridor(task="F[0,10] " + "!" * 98 + "in(O1, goal)"))
    assert math.isfinite(steps_finite_and_inside(scenario, np.zeros(6), steps=3)[-1])


def test_huge_box_bound_is_rejected_with_the_field():
    with pytest.raises(ScenarioError, match=r"world\.box: coordinates must be finite and within \+-1e\+06 m"):
        scenario_from_dict(corridor(world__box=[-1e300, 3.0, 0.0, 10.0]))
    with pytest.raises(ScenarioError, match=r"obstacles\[0\]\.box: coordinates"):
        scenario_from_dict(corridor(obstacles__0__box=[-1.0, 0.0, 0.0, 1e300]))


def test_huge_velocity_bound_is_rejected_not_an_overflow():
    data = corridor()
    data["robots"][0]["velocity_bound_mps"] = [1e308, 0.3]
    with pytest.raises(ScenarioError, match=r"robots\[0\]\.velocity_bound_mps.*maximum of 1000 substeps"):
        scenario_from_dict(data)


def test_integer_too_large_for_a_float_is_a_field_error():
    data = corridor()
    data["robots"][0]["mass_kg"] = 10 ** 400
    with pytest.raises(ScenarioError, match=r"robots\[0\]\.mass_kg must be a finite number"):
        scenario_from_dict(data)


def test_closing_vertex_is_dropped_and_the_region_works():
    closed = with_goal_polygon(GOAL_CORNERS + [GOAL_CORNERS[0]])
    scenario = scenario_from_dict(closed)
    polygon = scenario.region_map()["goal"]
    assert len(polygon.vertices) == 4 and np.all(np.isfinite(polygon.normals))
    assert polygon.signed_distance_xy(1.0, 8.0) == pytest.approx(0.75)
    steps_finite_and_inside(scenario, np.zeros(6), steps=5)
    # the same region as the box: equal polygons, equal robustness
    assert polygon == ConvexPolygon.from_vertices(GOAL_CORNERS)


def test_repeated_vertices_in_the_middle_are_dropped_too():
    polygon = ConvexPolygon.from_vertices([[0, 0], [1, 0], [1, 0], [1, 1], [0, 1], [0, 0], [0, 0]])
    assert polygon.vertices.tolist() == [[0, 0], [1, 0], [1, 1], [0, 1]]


def regular(k: int, step: int) -> list[float]:
    """Vertex k of a 5-point figure of radius 0.5 m around (1, 8): step 1 a pentagon, step 2 a pentagram."""
    angle = math.pi / 2 + 2 * math.pi * step * k / 5
    return [1 + 0.5 * math.cos(angle), 8 + 0.5 * math.sin(angle)]


def test_self_intersecting_pentagram_is_rejected():
    star = [regular(k, 2) for k in range(5)]
    with pytest.raises(ScenarioError, match=r"regions\[0\]\.polygon crosses itself"):
        scenario_from_dict(with_goal_polygon(star))
    pentagon = [regular(k, 1) for k in range(5)]
    ok = ConvexPolygon.from_vertices(pentagon)
    assert ok.signed_distance_xy(1.0, 8.0) == pytest.approx(0.5 * math.cos(math.pi / 5))


def test_task_shorter_than_a_control_period_is_rejected():
    with pytest.raises(ScenarioError, match=r"shorter than one control period \(0\.1 s\)"):
        scenario_from_dict(corridor(task="F[0,0.05] in(O1, goal)"))


def test_constant_task_gives_finite_rewards_that_sum_to_the_final_robustness():
    scenario = scenario_from_dict(corridor(task="F[0,20] true"))
    rewards = steps_finite_and_inside(scenario, np.zeros(6), steps=200)
    env = TransportEnv(scenario)
    limit = env.core.robustness_limit_m
    assert limit == pytest.approx(math.hypot(4.0, 10.0))
    assert sum(rewards) == pytest.approx(limit)
    false_task = scenario_from_dict(corridor(task="G[0,20] false"))
    assert sum(steps_finite_and_inside(false_task, np.zeros(6), steps=200)) == pytest.approx(-limit)


def test_fast_initial_velocity_is_caught_by_the_tunnelling_check():
    data = corridor()
    data["objects"][0]["velocity_mps"] = [0.0, 100.0]
    with pytest.raises(ScenarioError, match=r"objects\[0\]\.velocity_mps.*use substeps >= 350"):
        scenario_from_dict(data)
    data["substeps"] = 350
    scenario = scenario_from_dict(data)  # enough substeps: the object bounces between the walls, inside
    steps_finite_and_inside(scenario, np.zeros(6), steps=50)


def test_huge_thrust_is_caught_by_the_tunnelling_check():
    data = corridor()
    data["robots"][0]["thrust_limit_N"] = [1e5, 1e5]
    with pytest.raises(ScenarioError, match=r"robots\[0\]\.thrust_limit_N \(a full-thrust run across the world\)"):
        scenario_from_dict(data)


def test_reachable_speeds_within_the_envelope_stay_inside_the_world():
    """Full thrust into a wall and back for 30 s: no body tunnels out (the envelope's promise)."""
    scenario = load_scenario("corridor")
    steps_finite_and_inside(scenario, np.ones(6), steps=300)
    steps_finite_and_inside(scenario, -np.ones(6), steps=300)


def test_subnormal_inertia_is_rejected():
    data = corridor()
    data["robots"][0]["inertia_kgm2"] = 5e-324
    with pytest.raises(ScenarioError, match=r"robots\[0\]\.inertia_kgm2 = 4\.94066e-324 is below"):
        scenario_from_dict(data)


def test_torque_that_spins_a_robot_too_fast_is_rejected():
    data = corridor()
    data["robots"][1]["torque_limit_Nm"] = 1e6
    with pytest.raises(ScenarioError, match=r"robots\[1\]: torque_limit_Nm / inertia_kgm2 over tf_s"):
        scenario_from_dict(data)


@pytest.mark.parametrize("substeps", [10 ** 7, 1001])
def test_substeps_are_capped(substeps):
    with pytest.raises(ScenarioError, match=r"substeps must be <= 1000"):
        scenario_from_dict(corridor(substeps=substeps))


def test_too_many_control_periods_are_rejected():
    with pytest.raises(ScenarioError, match="control periods"):
        scenario_from_dict(corridor(control_period_s=1e-6))


def test_formula_is_parsed_once_and_the_scenario_stays_hashable_and_picklable():
    scenario = load_scenario("corridor")
    assert scenario.formula is scenario.formula
    again = load_scenario("corridor")
    assert scenario == again and hash(scenario) == hash(again)
    assert len({scenario, again}) == 1
    copy_ = pickle.loads(pickle.dumps(scenario))
    assert copy_ == scenario and copy_.formula == scenario.formula


def test_a_long_conjunction_loads_with_one_parse(monkeypatch):
    import impact_env.stl as stl

    calls = []
    parse = stl.parse

    def counting(text):
        calls.append(len(text))
        return parse(text)

    monkeypatch.setattr(stl, "parse", counting)
    task = "F[0,10] in(O1, goal) & " + " & ".join(["G[0,10] !in(R1, W1)"] * 2000)
    scenario = scenario_from_dict(corridor(task=task))
    assert len(scenario.formula.children) == 2001 and scenario.formula is scenario.formula
    assert len(calls) == 1


def test_shipped_scenarios_pass_the_limits():
    from impact_env import limits

    for name in ("corridor", "obstacle_avoidance", "throw_and_catch_exp"):
        scenario = load_scenario(name)
        kinds = [f"robots[{i}]" for i in range(len(scenario.robots))] + \
            [f"objects[{i}]" for i in range(len(scenario.objects))]
        v, _ = limits.fastest_speed(scenario.bodies, kinds, scenario.restitution, scenario.world_box, thrust=True)
        assert v * scenario.physics_dt_s <= min(b.radius_m for b in scenario.bodies)


# found by the fuzzers (tests/fuzz/)

def test_a_box_too_thin_for_its_edges_is_rejected():
    with pytest.raises(ScenarioError, match=r"obstacles\[0\]\.box must be at least 1e-06 m wide and high"):
        scenario_from_dict(corridor(obstacles__0__box=[-1.0, 0.0, 0.0, 3.8e-295]))


def test_robustness_over_an_interval_far_longer_than_the_trace():
    from impact_env.stl import parse, robustness

    trace = {"O1": np.linspace([1.0, 2.0], [1.0, 8.0], 31)}
    regions = load_scenario("corridor").region_map()
    assert robustness(parse("F[0,99999999999999999999] true"), trace, regions, dt=0.1) == math.inf
    far = robustness(parse("F[0,1e20] in(O1, goal)"), trace, regions, dt=0.1)
    assert far == robustness(parse("F[0,3] in(O1, goal)"), trace, regions, dt=0.1) == pytest.approx(0.75)
    late = robustness(parse("G[5,1e20] in(O1, goal)"), trace, regions, dt=0.1)
    assert late == pytest.approx(regions["goal"].signed_distance_xy(1.0, 8.0))


def test_a_subnormal_radius_is_a_scenario_error():
    data = corridor()
    data["robots"][0]["radius_m"] = 5e-324
    with pytest.raises(ScenarioError, match=r"even the maximum of 1000 substeps is too few"):
        scenario_from_dict(data)
