"""Faults of the tether fleet: each kind happens as documented and from the reset seed, and the expert survives
a failed anchor, a snapped tether, a dropped robot and winch speed errors, planning again without the anchor."""

from __future__ import annotations

import numpy as np
import pytest

from impact_env.errors import EnvConfigError
from impact_env.rollout import run_episode
from impact_env.tether.faults import FaultConfig, FaultSchedule, parse_faults
from impact_env.tether.gym_env import TetherEnv
from impact_env.tether.physics import TetherWorld
from impact_env.tether.station import load_station
from planners.tether.expert import TetherExpert
from tests.station_helpers import make_station


def _events(env, actions, steps):
    out = []
    for k in range(steps):
        _, _, _, _, info = env.step(actions(k))
        out += info["events"]
    return out, info


def test_a_failed_anchor_lets_go_and_refuses_later_attachments():
    st = make_station([[0, 0], [40, 0], [40, 40], [0, 40]], start=(20.0, 20.0), goal=(10.0, 10.0),
                      anchors={"points": [[40.0, 20.0], [0.0, 20.0]]})
    world = TetherWorld(st, "reel")
    world.attach(0, 1)
    world.step()
    world.fail_anchor(1)
    assert world.tether_anchor(0) is None and [e.kind for e in world.step()] == ["anchor_failed"]
    world.attach(1, 1, delay_s=2.0)
    events = [e for _ in range(3) for e in world.step()]
    assert [(e.kind, e.robot, e.anchor) for e in events] == [("refused", 1, 1)]
    world.attach(0, 0)
    assert world.snap(0) and world.tether_anchor(0) is None
    assert [e.kind for e in world.step()] == ["attached", "snapped"]
    world.drop_out(2)
    with pytest.raises(Exception, match="dropped out"):
        world.attach(2, 0)


@pytest.mark.parametrize("fault, kind", [({"anchor_failures": 1}, {"anchor_failed", "refused"}),
                                          ({"tether_snaps": 1}, {"snapped"}), ({"robot_dropouts": 1}, {"dropped_out"})])
def test_each_fault_happens_in_its_window_and_from_the_seed(fault, kind):
    def run(seed):
        env = TetherEnv("L", faults={**fault, "window_s": (20.0, 40.0)})
        env.reset(seed=seed)
        ex = TetherExpert(env.station)
        ex.reset(env)
        obs, info = env.core.observation(), env.core.reset_info()
        seen = []
        for _ in range(80):
            obs, _, _, _, info = env.step(ex.act(obs, info))
            seen += [(e["time"], e["kind"]) for e in info["events"] if e["kind"] in kind]
        return seen, info
    first, info = run(3)
    assert first and all(20.0 <= t <= 46.0 for t, _ in first)  # a refusal shows when the tether would start
    assert run(3)[0] == first  # the same seed, the same fault
    if "anchor_failed" in kind:
        assert info["failed_anchors"]
    if "dropped_out" in kind:
        assert info["dropped_robots"]


def test_winch_speed_errors_are_drawn_per_robot_and_the_rest_of_the_reset_is_unchanged():
    env = TetherEnv("L", faults={"winch_speed_error": (0.1, 0.3)}, initial_position_noise_m=0.3)
    plain = TetherEnv("L", initial_position_noise_m=0.3)
    obs, _ = env.reset(seed=5)
    obs_plain, _ = plain.reset(seed=5)
    np.testing.assert_array_equal(obs, obs_plain)  # the start position is drawn before the faults
    factors = env.core.schedule.winch_factors
    assert all(0.1 <= abs(f - 1.0) <= 0.3 for f in factors)
    assert env.core.world.winch_speeds_mps == tuple(0.1 * f for f in factors)


def test_fault_options_are_checked():
    with pytest.raises(EnvConfigError, match="robot_dropouts must be < the station's 3 robots"):
        TetherEnv("L", faults={"robot_dropouts": 3})
    with pytest.raises(EnvConfigError, match="no field 'bogus'"):
        TetherEnv("L", faults={"bogus": 1})
    with pytest.raises(EnvConfigError, match="winch_speed_error"):
        FaultConfig(winch_speed_error=(0.3, 0.1))
    assert parse_faults("anchor_failures=1,winch_speed_error=0.1:0.3") == {"anchor_failures": 1,
                                                                          "winch_speed_error": (0.1, 0.3)}
    with pytest.raises(EnvConfigError, match="not FIELD=VALUE"):
        parse_faults("anchor_failures")
    assert FaultSchedule.draw(None, 3, np.random.default_rng(0)).events == []


@pytest.mark.parametrize("fault", [{"anchor_failures": 1}, {"tether_snaps": 1}, {"robot_dropouts": 1},
                                   {"winch_speed_error": (0.1, 0.3)}])
@pytest.mark.parametrize("fidelity", ["kinematic", "reel"])
def test_the_expert_survives_a_fault(fault, fidelity):
    station = load_station("T")
    env = TetherEnv(station, fidelity=fidelity, faults=fault)
    expert = TetherExpert(station)
    for seed in (0, 1):
        res = run_episode(env, expert, seed=seed)
        assert res.success and res.final_info["speed_mps"] < station.rest_speed_mps, (seed, res.final_info)


def test_the_expert_plans_without_a_failed_anchor_reusing_the_geometry():
    station = load_station("L")
    expert = TetherExpert(station)
    first = expert.base_planner.plan()
    without = expert.base_planner.without([first.anchors[0]])
    assert first.anchors[0] not in without.plan().anchors
    assert without.seen[first.anchors[1]] is expert.base_planner.seen[first.anchors[1]]  # shared, not rebuilt
