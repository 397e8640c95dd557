"""Deliver and hold on stations the expert was not tuned on (tests/data/stations/): a serpentine that needs a
pull per leg, a heavy cargo on weak winches stopping in a pocket, a single robot (no second tether to brake
with), and seven hand-placed anchors with the goal in a corner (one of them the only way in)."""

from __future__ import annotations

import numpy as np
import pytest

from impact_env.rollout import run_episode
from impact_env.tether.core import ATTACH0, KEEP
from impact_env.tether.gym_env import TetherEnv
from impact_env.tether.station import load_station
from planners.tether.braking import BEHIND_COS
from planners.tether.errors import TetherInfeasibleError
from planners.tether.expert import SETTLE_MPS, TetherExpert
from planners.tether.reachability import ReachabilityPlanner
from tests.paths import DATA

STATIONS = DATA / "stations"
NAMES = ("serpentine", "heavy_pocket", "lone_robot", "sparse_corner")
FIDELITIES = ("kinematic", "reel", "force")


def _station(name: str):
    return load_station(str(STATIONS / f"{name}.toml"))


def _assert_held(station, res) -> None:
    info = res.final_info
    assert res.success, info
    assert info["speed_mps"] < station.rest_speed_mps
    assert info["time_at_rest_in_goal_s"] >= station.hold_s
    x0, x1, y0, y1 = station.goal_box
    x, y = res.positions[-1, 0]
    assert x0 <= x <= x1 and y0 <= y <= y1


def test_the_serpentine_needs_a_pull_per_leg():
    plan = ReachabilityPlanner(_station("serpentine")).plan()
    assert plan.switches >= 5


@pytest.mark.parametrize("fidelity", FIDELITIES)
@pytest.mark.parametrize("name", NAMES)
def test_the_expert_delivers_and_holds_on_the_stress_stations(name, fidelity):
    if name == "serpentine" and fidelity != "reel":
        pytest.skip("the serpentine's other fidelities run with -m slow")
    station = _station(name)
    res = run_episode(TetherEnv(station, fidelity=fidelity), TetherExpert(station), seed=0)
    _assert_held(station, res)


@pytest.mark.slow
@pytest.mark.parametrize("fidelity", ["kinematic", "force"])
def test_the_expert_delivers_and_holds_through_the_serpentine(fidelity):
    station = _station("serpentine")
    res = run_episode(TetherEnv(station, fidelity=fidelity), TetherExpert(station), seed=0)
    _assert_held(station, res)


@pytest.mark.parametrize("fidelity", ["reel", "force"])
def test_a_lone_robot_brakes_with_its_own_tether(fidelity):
    # with one robot nothing can be attached ahead while it pulls: it trades its anchor for the brake, and the
    # cargo coasts t_switch before the brake holds (it used to overshoot the box and shuttle back and forth)
    station = _station("lone_robot")
    env = TetherEnv(station, fidelity=fidelity, initial_position_noise_m=0.3)
    expert = TetherExpert(station)
    for seed in (0, 1, 2):
        res = run_episode(env, expert, seed=seed)
        _assert_held(station, res)
        assert res.final_info["switches"] <= 12, res.final_info  # no shuttling


def test_a_failure_of_the_only_anchor_into_the_corner_is_proved_fatal_and_the_cargo_left_still():
    station = _station("sparse_corner")
    planner = ReachabilityPlanner(station)
    way_in = 5  # (0, 13.5): the one anchor that pulls the cargo into the corner
    assert way_in in planner.plan().anchors
    with pytest.raises(TetherInfeasibleError):
        planner.without([way_in]).plan()
    env = TetherEnv(station, fidelity="reel", faults={"anchor_failures": 1})
    expert = TetherExpert(station)
    res = run_episode(env, expert, seed=0)  # this seed fails anchor 5 before the cargo reaches the corner
    assert res.final_info["failed_anchors"] == [way_in] and not res.success
    assert expert.stats.infeasible > 0 and res.final_info["speed_mps"] < station.rest_speed_mps


FAULTS = {"anchor": {"anchor_failures": 1}, "snap": {"tether_snaps": 1}, "winch": {"winch_speed_error": (0.1, 0.3)}}


@pytest.mark.slow
@pytest.mark.parametrize("name, fault", [("serpentine", "anchor"), ("serpentine", "snap"), ("serpentine", "winch"),
                                         ("lone_robot", "anchor"), ("lone_robot", "snap")])
def test_the_expert_survives_faults_on_the_stress_stations(name, fault):
    station = _station(name)
    env = TetherEnv(station, fidelity="reel", faults=FAULTS[fault], initial_position_noise_m=0.3)
    expert = TetherExpert(station)
    for seed in range(5):
        _assert_held(station, run_episode(env, expert, seed=seed))


@pytest.mark.slow
def test_a_lone_robot_with_a_slow_winch_keeps_the_cargo_in_the_box_to_the_end():
    # its brake leaves a 0.7 mm/s creep across the held tether, below the settle speed, that would carry the cargo
    # out of the box's lower edge 540 s later: the expert brakes it as soon as it sees it would
    station = _station("lone_robot")
    env = TetherEnv(station, fidelity="reel", faults=FAULTS["winch"], initial_position_noise_m=0.3)
    _assert_held(station, run_episode(env, TetherExpert(station), seed=0))


@pytest.mark.parametrize("vy_mps, leaves", [(-9e-4, True), (-4e-4, False)])
def test_a_creep_below_the_settle_speed_is_braked_when_it_would_leave_the_box_before_the_end(tmp_path, vy_mps,
                                                                                             leaves):
    # the cargo starts at rest in the box's centre, 0.5 m from its edges, and creeps down at 0.9 or 0.4 mm/s (below
    # the settle speed) for the 900 s of the episode: 0.81 m, out of the box, or 0.36 m, still in it
    text = (STATIONS / "lone_robot.toml").read_text()
    path = tmp_path / "lone_robot.toml"
    path.write_text(text.replace("start_m = [2.5, 1.5]", "start_m = [18.5, 12.5]"))
    station = load_station(str(path))
    assert abs(vy_mps) < SETTLE_MPS and (abs(vy_mps) * station.tf_s > 0.5) == leaves
    env = TetherEnv(station, fidelity="reel")
    expert = TetherExpert(station)
    obs, info = env.reset(seed=0)
    expert.reset(env)
    obs = obs.copy()
    obs[2:4] = (0.0, vy_mps)  # the observation's cargo velocity (m/s)
    command = int(expert.act(obs, info)[0])
    assert expert.plan is not None and not expert.plan.pulls  # in the goal already: nothing to pull
    if not leaves:
        assert command == KEEP
        return
    assert command >= ATTACH0, command  # the lone robot attaches a brake ...
    anchor = np.asarray(station.anchor_positions[command - ATTACH0]) - (18.5, 12.5)
    assert anchor[1] / np.hypot(*anchor) > -BEHIND_COS  # ... to an anchor behind the motion (above the cargo)
