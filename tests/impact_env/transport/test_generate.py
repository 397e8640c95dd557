"""The task generator (impact_env/transport/generate.py) and the scenario writer (scenario_toml.py).

The fast suite draws and checks tasks without planning; the planner's filter is tested in
tests/planners/test_task_filter.py.
"""

from __future__ import annotations

import hashlib
import math

import pytest
import tomllib
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from impact_env import ScenarioError, load_scenario, scenario_names
from impact_env.cli import main
from impact_env.stl import parse
from impact_env.transport.generate import (
    CLEARANCE_M,
    FAMILIES,
    FAMILY_LIMITS,
    GeneratedTaskError,
    check_task,
    generate_task,
    generate_toml,
    write_task,
)
from impact_env.transport.scenario import scenario_from_dict
from impact_env.transport.scenario_toml import scenario_from_toml, scenario_to_toml

seeds = st.integers(min_value=0, max_value=2**40)


@pytest.mark.parametrize("name", scenario_names())
def test_every_shipped_scenario_round_trips_through_the_writer(name):
    sc = load_scenario(name)
    again = scenario_from_toml(scenario_to_toml(sc, comment="a comment"), source=sc.source)
    assert again == sc
    assert again.task == sc.task and again.final_boxes == sc.final_boxes


def test_the_writer_keeps_a_polygon_and_nondefault_fields():
    sc = load_scenario("corridor")
    doc = {"name": "poly", "restitution": 0.5, "tf_s": 10.0, "task": "F[0,10] in(O1, tri)",
           "world": {"box": [0.0, 4.0, 0.0, 4.0]},
           "regions": [{"name": "tri", "polygon": [[1.0, 1.0], [3.0, 1.0], [2.0, 2.5]]}],
           "robots": [{"name": "R1", "mass_kg": 16.8, "radius_m": 0.2, "inertia_kgm2": 0.1594,
                       "position_m": [0.5, 0.5], "velocity_mps": [0.01, 0.0], "heading_rad": 0.3,
                       "thrust_limit_N": [2.8, 2.8], "torque_limit_Nm": 0.2}],
           "objects": [{"name": "O1", "mass_kg": 16.8, "radius_m": 0.2, "inertia_kgm2": 0.1594,
                        "position_m": [3.0, 3.0], "angular_velocity_radps": 0.1}]}
    poly = scenario_from_dict(doc)
    text = scenario_to_toml(poly)
    assert "polygon = [[" in text and "heading_rad = 0.3" in text and "velocity_mps = [0.01, 0.0]" in text
    assert scenario_from_toml(text, source="<dict>") == poly != sc


@pytest.mark.parametrize("family", FAMILIES)
def test_twenty_tasks_in_all_load_and_keep_the_rules(family):
    """The fast suite's draw: 5 seeds per family (20 in all), each loaded, checked and within its limits."""
    limits = FAMILY_LIMITS[family]
    for seed in range(5):
        sc = generate_task(family, seed)
        assert sc.name == f"{family}_{seed}"
        assert 2 <= len(sc.robots) <= min(4, limits.robots) and 1 <= len(sc.objects) <= limits.objects
        assert len(sc.regions) <= limits.regions and len(sc.obstacles) <= limits.obstacles
        assert all(len(o.polygon.vertices) <= limits.obstacle_vertices for o in sc.obstacles)
        check_task(sc)
        # every object ends held in a region, and every region the task names exists (the loader checks names)
        assert parse(sc.task).horizon_s == sc.tf_s


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(family=st.sampled_from(FAMILIES), seed=seeds)
def test_any_seed_gives_a_task_that_loads_round_trips_and_is_deterministic(family, seed):
    text = generate_toml(family, seed)
    assert generate_toml(family, seed) == text  # same seed, same file
    sc = scenario_from_toml(text)
    assert scenario_from_toml(scenario_to_toml(sc)) == sc  # both from "<toml>"
    check_task(sc)
    xmin, xmax, ymin, ymax = sc.world_box
    for body in sc.bodies:
        x, y = body.position_m
        assert xmin + body.radius_m <= x <= xmax - body.radius_m and ymin + body.radius_m <= y <= ymax - body.radius_m
    for a in range(len(sc.bodies)):
        for b in range(a + 1, len(sc.bodies)):
            p, q = sc.bodies[a], sc.bodies[b]
            assert math.dist(p.position_m, q.position_m) >= p.radius_m + q.radius_m + CLEARANCE_M - 1e-3


def test_different_seeds_give_different_tasks():
    texts = {generate_toml("obstacle_avoidance", seed) for seed in range(10)}
    assert len(texts) == 10


# The files of seed 0: a change here means every seed's task changed, so bump GENERATOR_VERSION.
SEED_0_SHA256 = {
    "throw_and_catch": "e73c194a65af57eec79a32fec34b250b399013a6c7ee4da5effec3f8a8762b49",
    "obstacle_avoidance": "011e8c4ccbd92a9d3d97ec72cbd9795c82b8b7918587e4afe2e15c6bb7d88c5a",
    "gaps": "e37fd2894e5ba779dea3ef0aed145e0f9f2f4ce1e102105e508bf26162d76b93",
    "timed_visits": "c882ef31285cb51dba9dd93f5134a829f792e305a84c7904e4967574b283da3f",
}


@pytest.mark.parametrize("family", FAMILIES)
def test_seed_0_is_the_same_file_on_every_machine(family):
    digest = hashlib.sha256(generate_toml(family, 0).encode()).hexdigest()
    assert digest == SEED_0_SHA256[family]


def test_bad_family_and_seed_are_typed_errors():
    with pytest.raises(GeneratedTaskError, match="did you mean 'gaps'"):
        generate_toml("gapz", 0)
    with pytest.raises(GeneratedTaskError, match="seed must be an integer"):
        generate_toml("gaps", -1)
    with pytest.raises(GeneratedTaskError, match="seed must be an integer"):
        generate_toml("gaps", 1.5)
    assert issubclass(GeneratedTaskError, ScenarioError)


def test_check_task_names_the_broken_rule():
    text = generate_toml("gaps", 0)
    sc = scenario_from_toml(text)
    tallest = max(sc.obstacles, key=lambda o: o.polygon.bounds[3] - o.polygon.bounds[2])
    wall = tallest.polygon.bounds
    doc = tomllib.loads(text)
    doc["robots"][0]["position_m"] = [wall[0] - 0.25, (wall[2] + wall[3]) / 2]  # the disc within the clearance
    doc["robots"][0]["final_position_m"] = doc["robots"][0]["position_m"]
    with pytest.raises(GeneratedTaskError, match=rf"R1's start .* within 0.2 m of obstacle '{tallest.name}'"):
        check_task(scenario_from_dict(doc))
    doc = tomllib.loads(text)
    doc["regions"][0]["box"] = [wall[0] - 0.5, wall[0] + 0.1, wall[2], wall[2] + 0.5]
    with pytest.raises(GeneratedTaskError, match=f"region 'goal1' overlaps obstacle '{tallest.name}'"):
        check_task(scenario_from_dict(doc))
    doc = tomllib.loads(text)
    doc["regions"][0]["box"] = [sc.world_box[1] - 0.5, sc.world_box[1] + 0.5, 1.0, 2.0]
    with pytest.raises(GeneratedTaskError, match="reaches outside the world box"):
        check_task(scenario_from_dict(doc))


def test_cli_generate_writes_the_file_and_a_folder(tmp_path, capsys):
    assert main(["generate", "--family", "timed_visits", "--seed", "4", "--toml", str(tmp_path / "t.toml")]) == 0
    assert (tmp_path / "t.toml").read_text() == generate_toml("timed_visits", 4)
    assert load_scenario(tmp_path / "t.toml").bodies == generate_task("timed_visits", 4).bodies
    assert main(["generate", "--family", "gaps", "--seed", "2", "--count", "4", "--out", str(tmp_path / "g")]) == 0
    assert sorted(p.name for p in (tmp_path / "g").iterdir()) == [f"gaps_{s}.toml" for s in range(2, 6)]
    assert main(["generate", "--family", "nope", "--toml", str(tmp_path / "x.toml")]) == 2
    assert "unknown task family 'nope'" in capsys.readouterr().err
    assert main(["generate", "--family", "gaps", "--count", "0"]) == 2


def test_write_task_creates_the_folder(tmp_path):
    path = write_task("throw_and_catch", 9, tmp_path / "a" / "b.toml")
    assert load_scenario(path).name == "throw_and_catch_9"
