"""Tether physics against closed forms: Eq. (5) under kinematic, winch limit and momentum under reel, the
tension law under force, restitution at a wall, snags at a corner, attach delays, determinism."""

from __future__ import annotations

import math

import numpy as np
import pytest

from impact_env.tether.physics import TetherError, TetherWorld, eq5_rk4_path
from impact_env.tether.station import load_station
from tests.station_helpers import make_station

ROOM = [[0, 0], [40, 0], [40, 40], [0, 40]]  # big enough that nothing touches a wall


def _room(anchors, start=(20.0, 5.0), **kwargs):
    return make_station(ROOM, start=start, goal=(20.0, 20.0), anchors={"points": anchors}, **kwargs)


def _positions(world, substeps):
    out = [world.position_m]
    for _ in range(substeps):
        world._substep()
        out.append(world.position_m)
    return np.array(out)


def test_kinematic_one_tether_is_a_straight_line_at_w():
    s = _room([[30.0, 40.0]])
    world = TetherWorld(s, "kinematic")
    world.attach(0, 0)
    path = _positions(world, 3000)
    t = np.arange(len(path)) * world.dt_s
    start, anchor = np.array(s.cargo.start_m), np.array([30.0, 40.0])
    u = (anchor - start) / np.linalg.norm(anchor - start)
    np.testing.assert_allclose(path, start + 0.1 * t[:, None] * u, atol=1e-9)  # closed form
    reference = eq5_rk4_path(s.cargo.start_m, [(30.0, 40.0)], 0.1, world.dt_s / 4, 4 * 3000)[::4]
    assert np.abs(path - reference).max() < 1e-6  # an independent RK4 of Eq. (5) at a finer step


def test_kinematic_arrival_releases_inside_the_stop_radius_and_stops():
    s = _room([[20.0, 0.0]], start=(20.0, 10.005))
    world = TetherWorld(s, "kinematic")
    world.attach(0, 0)
    events = []
    for _ in range(100):
        events += world.step()
    arrived = [e for e in events if e.kind == "arrived"]
    # 10.005 m to go, released at the first substep within 0.6 m: after ceil(9.405 / 0.01) = 941 substeps
    assert len(arrived) == 1 and arrived[0].time_s == pytest.approx(math.ceil(9.405 / 0.01) * 0.1)
    assert world.tether_anchor(0) is None and world.velocity_mps == (0.0, 0.0)
    assert math.dist(world.position_m, (20.0, 0.0)) <= 0.6
    assert world.winch_work_J == pytest.approx(1.0 * 941 * 0.01, rel=1e-9)  # Eq. 5's tension F_max, 9.41 m


@pytest.mark.parametrize("a1,a2", [((5.0, 40.0), (35.0, 40.0)), ((0.0, 30.0), (40.0, 12.0))])
def test_kinematic_two_tethers_follow_the_hyperbola_at_2w_cos_half_theta(a1, a2):
    s = _room([list(a1), list(a2)], start=(17.0, 5.0))
    world = TetherWorld(s, "kinematic")
    world.attach(0, 0)
    world.attach(1, 1)
    path = _positions(world, 1500)
    d1 = np.linalg.norm(path - a1, axis=1)
    d2 = np.linalg.norm(path - a2, axis=1)
    assert np.abs((d1 - d2) - (d1[0] - d2[0])).max() < 1e-9  # both distances shrink at the same rate
    mid = 0.5 * (path[1:] + path[:-1])
    u1 = (np.array(a1) - mid) / np.linalg.norm(np.array(a1) - mid, axis=1)[:, None]
    u2 = (np.array(a2) - mid) / np.linalg.norm(np.array(a2) - mid, axis=1)[:, None]
    theta = np.arccos(np.clip(np.einsum("ij,ij->i", u1, u2), -1, 1))
    speed = np.linalg.norm(np.diff(path, axis=0), axis=1) / world.dt_s
    np.testing.assert_allclose(speed, 2 * 0.1 * np.cos(theta / 2), rtol=1e-6)
    assert d1[-1] < d1[0] - 3.0  # it did go somewhere


def test_reel_winch_limit_then_reel_speed_then_free_drift():
    s = _room([[20.0, 40.0]], start=(20.0, 5.0))  # m = 20 kg, F = 1 N, dt = 0.1 s: 0.005 m/s per substep
    world = TetherWorld(s, "reel")
    world.attach(0, 0)
    speeds, impulses = [], []
    for _ in range(60):
        world._substep()
        speeds.append(world.velocity_mps[1])
        impulses.append(world._tethers[0].joint.impulse)
        assert abs(world.velocity_mps[0]) < 1e-15
    n = np.arange(1, 61)
    np.testing.assert_allclose(speeds, np.minimum(0.1, n * 1.0 * 0.1 / 20.0), rtol=0, atol=1e-12)
    assert max(impulses) <= 1.0 * 0.1 + 1e-15  # the winch never exceeds its force limit
    # once at w, the tether shortens by exactly w dt per substep
    before = world.tether_length_m(0)
    world._substep()
    assert before - world.tether_length_m(0) == pytest.approx(0.1 * 0.1, abs=1e-12)
    world.release(0)
    v = world.velocity_mps
    for _ in range(50):  # released: the cargo keeps its momentum (no damping, no gravity)
        world._substep()
        assert world.velocity_mps == v


def test_reel_two_tethers_taut_move_at_w_over_cos_half_theta_and_conserve_momentum():
    s = _room([[10.0, 40.0], [30.0, 40.0]], start=(20.0, 5.0), winch=50.0, substeps=100)
    a1, a2 = map(tuple, s.anchor_positions)  # anchors are numbered along the walls
    world = TetherWorld(s, "reel")
    world.attach(0, 0)
    world.attach(1, 1)
    m = s.cargo.mass_kg
    momentum = np.zeros(2)
    work = 0.0
    for k in range(2000):
        p0, v0 = np.array(world.position_m), np.array(world.velocity_mps)
        predicted = p0 + v0 * world.dt_s
        units = [(np.array(a) - predicted) / np.linalg.norm(np.array(a) - predicted) for a in (a1, a2)]
        world._substep()
        v1 = np.array(world.velocity_mps)
        impulse = sum(t.joint.impulse * u for t, u in zip(world._tethers, units))
        momentum += impulse
        work += float(impulse @ (0.5 * (v0 + v1)))
        np.testing.assert_allclose(m * v1, m * v0 + impulse, atol=1e-12)  # momentum: m dv = sum of impulses
        if k > 200:  # both taut: along the bisector (x stays 20), each distance shrinking at w
            cos_half = math.cos(0.5 * math.acos(float(units[0] @ units[1])))
            assert abs(world.velocity_mps[0]) < 1e-8
            assert math.hypot(*world.velocity_mps) == pytest.approx(0.1 / cos_half, rel=1e-9)
    assert 0.5 * m * float(np.dot(world.velocity_mps, world.velocity_mps)) == pytest.approx(work, rel=1e-12)
    assert world.winch_work_J == pytest.approx(work, rel=1e-12)


def test_force_tension_law_closed_form():
    s = _room([[20.0, 40.0]], start=(20.0, 5.0))
    world = TetherWorld(s, "force")
    world.attach(0, 0)
    g = world.dt_s * 1.0 / (20.0 * 0.1)
    vs, ys = [], [world.position_m[1]]
    for _ in range(200):
        world._substep()
        vs.append(world.velocity_mps[1])
        ys.append(world.position_m[1])
    n = np.arange(1, 201)
    np.testing.assert_allclose(vs, 0.1 * (1 - (1 - g) ** n), rtol=0, atol=1e-13)
    # pymunk moves with the velocity before the step: y_n = y_0 + dt * sum_{j < n} v_j
    np.testing.assert_allclose(np.diff(ys)[1:], world.dt_s * np.array(vs[:-1]), atol=1e-12)
    assert world.winch_work_J == pytest.approx(0.5 * 20.0 * vs[-1] ** 2, rel=1e-9)


@pytest.mark.parametrize("fidelity", ["reel", "force"])
def test_wall_bounce_keeps_restitution(fidelity):
    s = _room([[20.0, 40.0]], start=(20.0, 37.0), stop=0.6, restitution=0.36)
    world = TetherWorld(s, fidelity)
    world.attach(0, 0)
    bounced = None
    for _ in range(1000):
        before = world.velocity_mps
        world._substep()
        if before[1] > 0 and world.velocity_mps[1] < 0:
            bounced = (before, world.velocity_mps)
            break
    assert bounced is not None and world.wall_contacts == 1
    (vx0, vy0), (vx1, vy1) = bounced
    assert vy1 == pytest.approx(-0.36 * vy0, rel=1e-9) and vx1 == pytest.approx(vx0, abs=1e-15)


def test_snag_when_the_cargo_passes_the_notch():
    """L map: a tether from the top of the shaft to the shaft's bottom anchor (3.75, 0) snags on the notch
    (5, 10) once the cargo, pulled into the arm, has x > 3.75 + 0.125 y."""
    s = load_station("L")
    bottom = next(a.index for a in s.anchors if a.position_m == (3.75, 0.0))
    right = next(a.index for a in s.anchors if a.position_m == (20.0, 13.75))
    world = TetherWorld(s, "kinematic", start_m=(3.5, 12.0))
    world.attach(0, right)
    world.attach(1, bottom)
    track = [world.position_m]
    events = []
    for _ in range(600):
        world._substep()
        track.append(world.position_m)
        events += world._events
        world._events = []
        if events and events[-1].kind == "snagged":
            break
    assert [(e.kind, e.robot) for e in events] == [("attached", 0), ("attached", 1), ("snagged", 1)]
    (x0, y0), (x1, y1) = track[-2], track[-1]
    assert x0 - 3.75 - 0.125 * y0 <= 0.0 < x1 - 3.75 - 0.125 * y1
    assert world.tether_anchor(1) is None and world.is_pulling(0)


def test_attach_delay_blocked_and_errors():
    s = load_station("L")
    world = TetherWorld(s, "kinematic")
    world.attach(0, 20, delay_s=5.0)
    assert not world.is_pulling(0) and world.attach_remaining_s(0) == 5.0
    for _ in range(5):
        assert world.step() == [] or world.time_s == 5.0
    assert world.position_m == s.cargo.start_m and world.is_pulling(0)
    with pytest.raises(TetherError, match="robot 0 already holds anchor 20"):
        world.attach(0, 3)
    with pytest.raises(TetherError, match="anchor must be in 0..27"):
        world.attach(1, 28)
    hidden = TetherWorld(s, "kinematic")
    hidden.attach(0, 11)  # (18.75, 10) cannot be seen from the start
    assert [e.kind for e in hidden.step()] == ["blocked"] and hidden.tether_anchor(0) is None
    with pytest.raises(TetherError, match="fidelity must be one of"):
        TetherWorld(s, "rope")
    with pytest.raises(TetherError, match="pull_speed_mps must be"):
        TetherWorld(s, "reel", pull_speed_mps=-1.0)


@pytest.mark.parametrize("fidelity", ["kinematic", "reel", "force"])
def test_bitwise_determinism_and_fresh_worlds(fidelity):
    s = load_station("L")

    def run():
        world = TetherWorld(s, fidelity)
        world.attach(0, 20)
        world.attach(1, 21)
        out = []
        for _ in range(150):
            world.step()
            out.append((*world.position_m, *world.velocity_mps, world.winch_work_J))
        return out

    assert run() == run()


@pytest.mark.parametrize("name,fidelity", [("L", "kinematic"), ("L", "reel"), ("iss_chain", "kinematic"),
                                           ("iss_chain", "reel"), ("dead_end", "reel")])
def test_cached_checks_give_the_exact_trajectories(name, fidelity):
    """Skipping line-of-sight and wall tests while they provably cannot change changes nothing, bit for bit,
    over random tether commands that snag, arrive and slide along walls."""
    s = load_station(name)

    def run(cache):
        rng = np.random.default_rng(11)
        world = TetherWorld(s, fidelity, cache_checks=cache)
        out = []
        for _ in range(400):
            visible = np.flatnonzero(s.line_of_sight(world.position_m))
            for robot in range(2):
                if world.tether_anchor(robot) is not None and rng.uniform() < 0.03:
                    world.release(robot)
                if world.tether_anchor(robot) is None and rng.uniform() < 0.2 and len(visible):
                    anchor = int(rng.choice(visible))
                    if anchor not in (world.tether_anchor(0), world.tether_anchor(1)):
                        world.attach(robot, anchor)
            events = world.step()
            out.append((*world.position_m, *world.velocity_mps, tuple((e.kind, e.robot) for e in events)))
        return out

    cached, exact = run(True), run(False)
    assert cached == exact
    kinds = {kind for step in exact for kind, _ in step[4]}
    assert kinds & {"snagged", "arrived"}, kinds  # the checks did fire
