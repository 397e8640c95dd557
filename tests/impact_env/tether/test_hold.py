"""Deliver and hold: the held winch at every fidelity against closed forms, the hold task's robustness and
``info``, and the expert bringing the cargo to rest in the goal box on every shipped station at every fidelity."""

from __future__ import annotations

import math

import numpy as np
import pytest

from impact_env.rollout import run_episode
from impact_env.stl import parse, robustness
from impact_env.tether.gym_env import TetherEnv
from impact_env.tether.physics import TetherWorld
from impact_env.tether.station import load_station, station_names
from planners.tether.expert import TetherExpert
from tests.station_helpers import make_station

ROOM = [[0, 0], [40, 0], [40, 40], [0, 40]]


def _room(**kwargs):
    # anchors: 0 = (20, 0), 1 = (40, 20), 2 = (0, 20)
    return make_station(ROOM, start=(20.0, 20.0), goal=(10.0, 10.0),
                        anchors={"points": [[40.0, 20.0], [0.0, 20.0], [20.0, 0.0]]}, **kwargs)


def _pull_then_hold(fidelity: str, steps: int = 40):
    """One tether pulls the cargo toward (40, 20) for 20 s, then a held tether from (0, 20) and a hold of the
    pulling one stop it."""
    st = _room()
    world = TetherWorld(st, fidelity)
    world.attach(0, 1)
    for _ in range(20):
        world.step()
    world.attach(1, 2)
    world.hold(1)
    world.hold(0)
    states = [world.state()]
    for _ in range(steps):
        world.step()
        states.append(world.state())
    return st, world, np.array(states)


def test_reel_a_held_tether_stops_the_cargo_within_the_winch_limit_without_pulling_it_back():
    st, world, s = _pull_then_hold("reel")
    # moving away from the held anchor at 0.1 m/s: the joint at 1 N stops 20 kg in 2 s over v^2 m / (2 F) = 0.1 m
    assert s[0, 2] == pytest.approx(0.1, abs=1e-3)
    assert abs(s[-1, 2]) < 1e-9 and np.all(s[3:, 2] > -1e-9)  # stopped, and no rebound toward the anchor
    assert s[-1, 0] - s[0, 0] == pytest.approx(0.1, abs=0.01)
    assert world.is_holding(0) and world.is_holding(1)


def test_force_a_held_winch_brakes_with_the_time_constant_m_w_over_f():
    st, world, s = _pull_then_hold("force", steps=20)
    tau = st.cargo.mass_kg * st.pull_speed_mps / st.winch_force_limit_N  # 2 s
    # held tension F * v / w: v(t) = v0 exp(-t / tau), at the substeps' Euler rate (1 - dt / tau) per substep
    v0 = s[0, 2]
    for k in (1, 4, 10):
        assert s[k, 2] == pytest.approx(v0 * (1 - 0.1 / tau) ** (10 * k), rel=1e-9)
    assert s[-1, 2] < 1e-4 * v0


def test_kinematic_holds_stop_the_cargo_and_a_held_tether_never_lengthens():
    st = _room()
    world = TetherWorld(st, "kinematic")
    world.attach(0, 1)
    world.attach(1, 2)
    world.hold(1)  # pulling toward (40, 20) with (0, 20) held behind: nothing can lengthen it, so no motion
    before = world.state()
    world.step()
    assert world.state()[:2] == pytest.approx(before[:2], abs=1e-12)
    world.release(1)
    world.attach(1, 0)
    world.hold(1)  # held across the motion: the cargo moves on the circle around (20, 0)
    for _ in range(10):
        world.step()
    x, y = world.state()[:2]
    assert math.hypot(x - 20.0, y) <= 20.0 + 1e-9
    world.hold(0)
    world.step()
    assert world.velocity_mps == (0.0, 0.0)


def test_kinematic_winch_work_is_eq5s_tension_times_the_reel_in_rate():
    st = _room()
    world = TetherWorld(st, "kinematic")
    world.attach(0, 1)
    for _ in range(30):
        world.step()
    assert world.winch_work_J == pytest.approx(st.winch_force_limit_N * 0.1 * 30, rel=1e-9)  # F * distance
    two = TetherWorld(make_station(ROOM, start=(20.0, 5.0), goal=(10.0, 10.0),
                                   anchors={"points": [[0.0, 25.0], [40.0, 25.0]]}), "kinematic")
    two.attach(0, 0)
    two.attach(1, 1)
    x0 = np.array(two.position_m)
    two._substep()
    # each tether: F times its reel-in rate w (1 + cos theta); the drag F / w per m/s times the speed squared
    theta = math.pi / 2.0  # the tethers from (20, 5) to (0, 25) and (40, 25) meet at 90 degrees
    assert two.winch_work_J == pytest.approx(2 * 1.0 * 0.1 * (1 + math.cos(theta)) * two.dt_s, rel=1e-3)
    assert np.linalg.norm(np.array(two.position_m) - x0) / two.dt_s == pytest.approx(2 * 0.1 * math.cos(theta / 2),
                                                                                    rel=1e-3)


def test_the_hold_task_needs_the_whole_hold_at_rest_in_the_box():
    st = load_station("L")
    formula, regions = parse(st.task), st.region_map()
    g, t = np.array(st.goal_center_m), st.drift_time_s
    n = 601
    at_rest = {"cargo": np.tile(g, (n, 1)), "drift": np.zeros((n, 2))}
    assert robustness(formula, at_rest, regions, dt=1.0) > 0
    moving = {"cargo": np.tile(g, (n, 1)), "drift": np.tile([0.021 * t, 0.0], (n, 1))}
    assert robustness(formula, moving, regions, dt=1.0) < 0  # in the box, but not at rest
    brief = dict(at_rest, cargo=np.array([g if 100 <= k < 125 else g + 5.0 for k in range(n)]))
    assert robustness(formula, brief, regions, dt=1.0) < 0  # 25 s in the box: short of the 30 s hold
    held = dict(at_rest, cargo=np.array([g if 100 <= k <= 130 else g + 5.0 for k in range(n)]))
    assert robustness(formula, held, regions, dt=1.0) > 0


def test_info_reports_the_time_in_the_goal_and_the_speed():
    env = TetherEnv("L", fidelity="reel")  # with inertia: a cargo set moving keeps moving
    env.reset(seed=0)
    core = env.core
    core.world.cargo.position = core.station.goal_center_m
    _, _, _, _, info = env.step([0, 0, 0])
    assert info["time_to_goal_s"] == 1.0 and info["time_in_goal_s"] == 1.0 and info["speed_mps"] == 0.0
    assert info["time_at_rest_in_goal_s"] == 1.0
    core.world.cargo.velocity = (0.05, 0.0)  # 5 cm of the box's 50 cm half-width in this step
    _, _, _, _, info = env.step([0, 0, 0])
    assert info["time_at_rest_in_goal_s"] == 0.0 and info["time_in_goal_s"] == 2.0
    assert info["speed_mps"] == pytest.approx(0.05)


@pytest.mark.parametrize("fidelity", ["kinematic", "reel", "force"])
@pytest.mark.parametrize("name", station_names())
def test_the_expert_delivers_and_holds_on_every_station_at_every_fidelity(name, fidelity):
    station = load_station(name)
    env = TetherEnv(station, fidelity=fidelity)
    res = run_episode(env, TetherExpert(station), seed=0)
    info = res.final_info
    assert res.success and info["speed_mps"] < station.rest_speed_mps
    assert info["time_at_rest_in_goal_s"] >= station.hold_s  # in the box, at rest, for the whole hold
    x0, x1, y0, y1 = station.goal_box
    x, y = res.positions[-1, 0]
    assert x0 <= x <= x1 and y0 <= y <= y1
