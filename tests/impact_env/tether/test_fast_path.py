"""The tether world's speed-ups change no trajectory: the C-call substep loops against pymunk's properties, the
world restarted in place against a fresh one, the cached line of sight and the O(1) task monitor against the
exact ones, the incremental observation against one built from zeros, and scripted episodes against digests
recorded before any of them (tests/data/tether_trajectories.json, recorded at commit 416eccf)."""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest
import shapely

from impact_env.stl import OnlineMonitor, parse
from impact_env.tether.core import TetherCore
from impact_env.tether.physics import TetherWorld
from impact_env.tether.sight import SightCache
from impact_env.tether.station import load_station, station_names
from impact_env.tether.task_monitor import HoldMonitor, task_monitor
from tests.paths import DATA

DIGESTS = json.loads((DATA / "tether_trajectories.json").read_text())


def scripted(station, fidelity: str, seed: int, **world) -> tuple[str, float]:
    """The recording script: every 20 steps each of two robots may let go and attach to a visible anchor."""
    rng = np.random.default_rng(seed)
    w = TetherWorld(station, fidelity, **world)
    h = hashlib.sha256()
    for step in range(240):
        if step % 20 == 0:
            los = np.flatnonzero(station.line_of_sight(w.position_m))
            for robot in range(2):
                if w.tether_anchor(robot) is not None and rng.uniform() < 0.5:
                    w.release(robot)
                if w.tether_anchor(robot) is None and len(los):
                    a = int(rng.choice(los))
                    if a not in [w.tether_anchor(r) for r in range(station.n_robots)]:
                        w.attach(robot, a, delay_s=float(rng.choice([0.0, 5.0])))
        events = w.step()
        x, y = w.position_m
        vx, vy = w.velocity_mps
        h.update(np.array([x, y, vx, vy], dtype=np.float64).tobytes())
        for e in events:
            h.update(f"{e.time_s!r}{e.kind}{e.robot}{e.anchor}".encode())
    return h.hexdigest(), w.winch_work_J


@pytest.mark.parametrize("fast", [True, False])
@pytest.mark.parametrize("key", sorted(DIGESTS))
def test_trajectories_are_those_recorded_before_the_speed_ups(key, fast):
    name, fidelity, seed = key.split("/")
    digest, work = scripted(load_station(name), fidelity, int(seed), fast=fast)
    assert digest == DIGESTS[key]["sha256"]
    if fidelity != "kinematic":  # the kinematic winch work changed on purpose (Eq. 5's tension)
        assert work == DIGESTS[key]["winch_work_J"]


def _episode(world, station, rng, h) -> None:
    for step in range(120):
        if step % 12 == 0:
            los = np.flatnonzero(station.line_of_sight(world.position_m))
            for robot in range(2):
                if world.tether_anchor(robot) is not None and rng.uniform() < 0.5:
                    world.release(robot)
                if world.tether_anchor(robot) is None and len(los):
                    a = int(rng.choice(los))
                    if a not in [world.tether_anchor(r) for r in range(station.n_robots)]:
                        world.attach(robot, a, delay_s=float(rng.choice([0.0, 2.0])))
                if rng.uniform() < 0.2:
                    world.hold(robot)
        for e in world.step():
            h.update(f"{e.time_s!r}{e.kind}{e.robot}{e.anchor}".encode())
        h.update(np.array(world.state()).tobytes() + repr((world.winch_work_J, world.wall_contacts)).encode())


@pytest.mark.parametrize("fidelity", ["kinematic", "reel", "force"])
@pytest.mark.parametrize("name", ["L", "iss_chain"])
def test_a_restarted_world_flies_as_a_fresh_one(name, fidelity):
    station = load_station(name)
    fresh, reused = hashlib.sha256(), hashlib.sha256()
    rng_a, rng_b = np.random.default_rng(3), np.random.default_rng(3)
    world = TetherWorld(station, fidelity)
    for episode in range(4):
        _episode(TetherWorld(station, fidelity), station, rng_a, fresh)
        _episode(world.restart() if episode else world, station, rng_b, reused)
    assert fresh.hexdigest() == reused.hexdigest()


@pytest.mark.parametrize("fidelity", ["kinematic", "reel", "force"])
def test_holds_and_winch_errors_fly_the_same_through_both_paths(fidelity):
    station = load_station("T")
    digests = []
    for fast in (True, False):
        h = hashlib.sha256()
        world = TetherWorld(station, fidelity, winch_speeds_mps=[0.08, 0.12, 0.1], fast=fast)
        _episode(world, station, np.random.default_rng(7), h)
        digests.append(h.hexdigest())
    assert digests[0] == digests[1]


@pytest.mark.parametrize("name", station_names())
def test_the_sight_cache_gives_the_exact_masks(name):
    station = load_station(name)
    cache, free = SightCache(station), station.free_space()
    rng = np.random.default_rng(0)
    x = np.array(station.cargo.start_m)
    for k in range(1500):
        step = rng.normal(size=2) * (0.15 if k % 200 else 5.0)  # now and then a jump (a reset)
        if free.covers(shapely.Point(*(x + step))):
            x = x + step
        mask = (cache.restart(*x) if k % 300 == 0 else cache.mask(*x)).copy()
        np.testing.assert_array_equal(mask, station.line_of_sight(x))
    assert cache.exact_tests < 1500 * station.n_anchors / 2  # it does cache


def test_the_hold_monitor_is_the_stl_monitor():
    station = load_station("L")
    rng = np.random.default_rng(1)
    regions = station.region_map()
    for _ in range(200):
        t, h, dt = int(rng.integers(1, 30)), int(rng.integers(0, 12)), float(rng.choice([1.0, 0.5]))
        text = (f"F[0,{t * dt}] G[0,{h * dt}] (in(cargo, goal) & in(drift, rest))" if h
                else f"F[0,{t * dt}] in(cargo, goal)")
        fast, exact = task_monitor(parse(text), regions, dt), OnlineMonitor(parse(text), regions, dt)
        assert isinstance(fast, HoldMonitor) and fast.horizon_steps == exact.horizon_steps
        g = np.array(station.goal_center_m)
        for _ in range(t + h + 5):
            x, v = g + rng.normal(size=2) * rng.choice([0.1, 1.0]), rng.normal(size=2) * rng.choice([0.001, 0.05])
            positions = station.task_positions(x[0], x[1], v[0], v[1])
            assert fast.update(positions) == exact.update(positions)
    assert not isinstance(task_monitor(parse("G[0,10] F[0,5] in(cargo, goal)"), regions, 1.0), HoldMonitor)


def _reference_observation(core: TetherCore, order) -> np.ndarray:
    """The observation built from zeros, as version 0.2 built it."""
    world, n = core.world, core.n_anchors
    x, y, vx, vy = core._state[0][:4]
    out = np.zeros(core.obs_size)
    out[:4] = (x, y, vx, vy)
    for slot, robot in enumerate(order):
        anchor = world.tether_anchor(robot)
        if anchor is not None:
            base = 4 + slot * core.robot_block
            out[base + anchor] = 1.0
            out[base + n] = world.attach_remaining_s(robot) / core.station.switch_time_s
            out[base + n + 1] = world.tether_length_m(robot)
            if core.hold_command is not None and world.is_holding(robot):
                out[base + n + 2] = 1.0
    out[core._los0: core._los0 + n] = core.station.line_of_sight((x, y))
    out[-1] = max(0.0, 1.0 - core.step_count / core.horizon_steps)
    return np.clip(out.astype(np.float32), core.obs_low, core.obs_high)


@pytest.mark.parametrize("version", [0, 1])
def test_the_incremental_observation_is_the_one_built_from_zeros(version):
    core = TetherCore("alcove", fidelity="reel", version=version)
    rng = np.random.default_rng(2)
    for _ in range(3):
        core.reset(rng)
        for _ in range(120):
            core.step([int(rng.integers(0, core.n_commands)) if rng.uniform() < 0.1 else 0 for _ in range(3)])
            np.testing.assert_array_equal(core.observation(), _reference_observation(core, range(3)))
            for robot in range(3):
                order = [robot] + [r for r in range(3) if r != robot]
                np.testing.assert_array_equal(core.agent_observation(robot), _reference_observation(core, order))
