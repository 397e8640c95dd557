"""Physics against closed forms: the paper's Eq. 5 (point masses, head-on) and Eq. 6-7 (discs, oblique),
momentum conservation, energy conservation for e = 1, thrust and torque limits, no tunnelling."""

from __future__ import annotations

import math

import numpy as np
import pytest

from impact_env.transport.core import TransportCore
from impact_env.transport.physics import World
from tests.helpers import two_body


def eq5(m_r: float, m_o: float, v_r: float, v_o: float, e: float) -> tuple[float, float]:
    """Eq. (5): post-impact normal velocities of a robot and an object."""
    s = m_r + m_o
    return ((m_r - e * m_o) / s * v_r + (1 + e) * m_o / s * v_o,
            (1 + e) * m_r / s * v_r + (m_o - e * m_r) / s * v_o)


def run_until_separated(world: World, max_steps: int = 2000):
    """Step with zero thrust one substep at a time; return the impact event and the contact normal.

    pymunk integrates positions before detecting contacts, so the positions at detection are the
    previous positions advanced by one substep at the previous velocities; the normal of Eq. 6 is the
    line of centres there.
    """
    robot, obj = world.bodies[0], world.bodies[1]
    normal = None
    since_touch = 0
    for _ in range(max_steps):
        pr = np.array(robot.position) + np.array(robot.velocity) * world.dt_s
        po = np.array(obj.position) + np.array(obj.velocity) * world.dt_s
        events = world.step([(0.0, 0.0, 0.0)])
        if normal is None and world._open:
            normal = (po - pr) / np.linalg.norm(po - pr)
        if events:
            return events[0], normal if normal is not None else (po - pr) / np.linalg.norm(po - pr)
        if normal is not None:
            since_touch += 1
            if since_touch > 20:  # e = 0: the discs move on together and never separate
                return world.flush_impacts()[0], normal
    raise AssertionError("no impact happened")


@pytest.mark.parametrize("e", [0.0, 0.47, 0.75, 1.0])
@pytest.mark.parametrize("m_r,m_o", [(16.8, 16.8), (16.8, 4.2), (2.0, 20.0)])
@pytest.mark.parametrize("v_o", [0.0, -0.2])
def test_head_on_matches_eq5(e, m_r, m_o, v_o):
    sc = two_body(e=e, m_robot=m_r, m_object=m_o, robot_vel=(0.3, 0.0), object_vel=(v_o, 0.0),
                  control_period_s=0.01, substeps=1)
    world = World(sc)
    event, _ = run_until_separated(world)
    vr, vo = eq5(m_r, m_o, 0.3, v_o, e)
    assert event.velocity_after("R1") == pytest.approx((vr, 0.0), abs=1e-9)
    assert event.velocity_after("O1") == pytest.approx((vo, 0.0), abs=1e-9)
    # the logged impulse is the object's momentum change
    assert event.impulse_Ns == pytest.approx(m_o * abs(vo - v_o), rel=1e-9)
    assert event.velocity_before("R1") == pytest.approx((0.3, 0.0))
    assert (event.a, event.b) in {("R1", "O1"), ("O1", "R1")}


@pytest.mark.parametrize("e", [0.3, 0.75, 1.0])
@pytest.mark.parametrize("m_r,m_o,offset", [(16.8, 16.8, 0.15), (16.8, 5.0, -0.05), (3.0, 16.8, 0.3)])
def test_oblique_disc_impact_matches_eq6_7(e, m_r, m_o, offset):
    """Eq. 6-7: in the contact frame the normal components follow Eq. 5, the tangential ones are kept."""
    sc = two_body(e=e, m_robot=m_r, m_object=m_o, robot_vel=(0.25, 0.05), object_vel=(-0.05, 0.0),
                  object_pos=(4.0, 5.0 + offset), control_period_s=0.01, substeps=1)
    world = World(sc)
    vr0, vo0 = np.array([0.25, 0.05]), np.array([-0.05, 0.0])
    event, n = run_until_separated(world)
    t = np.array([-n[1], n[0]])
    vr_n, vo_n = eq5(m_r, m_o, vr0 @ n, vo0 @ n, e)
    expected_r = vr_n * n + (vr0 @ t) * t  # Eq. (7): rotate back to the world frame
    expected_o = vo_n * n + (vo0 @ t) * t
    assert np.array(event.velocity_after("R1")) == pytest.approx(expected_r, abs=1e-9)
    assert np.array(event.velocity_after("O1")) == pytest.approx(expected_o, abs=1e-9)
    # frictionless contact through the centres: no spin is created
    assert world.bodies[0].angular_velocity == pytest.approx(0.0, abs=1e-12)
    assert world.bodies[1].angular_velocity == pytest.approx(0.0, abs=1e-12)


def test_momentum_conserved_in_impact():
    sc = two_body(e=0.6, m_robot=16.8, m_object=7.0, robot_vel=(0.3, 0.1), object_vel=(-0.1, 0.02),
                  object_pos=(4.0, 5.2))
    world = World(sc)
    p0 = sum(b.mass * np.array(b.velocity) for b in world.bodies)
    for _ in range(100):
        world.step([(0.0, 0.0, 0.0)])
    p1 = sum(b.mass * np.array(b.velocity) for b in world.bodies)
    assert np.array(world.bodies[1].velocity) != pytest.approx(np.array([-0.1, 0.02]))  # they did collide
    assert p1 == pytest.approx(p0, abs=1e-12)


def test_energy_conserved_with_elastic_walls_and_bodies():
    """e = 1: 100 s of bouncing between two discs and the four walls keeps the kinetic energy."""
    sc = two_body(e=1.0, robot_pos=(2.0, 3.0), robot_vel=(0.9, 0.4), object_pos=(3.0, 6.0),
                  object_vel=(-0.5, 0.7), box=(0.0, 4.0, 0.0, 8.0))
    world = World(sc)

    def energy() -> float:
        return sum(0.5 * b.mass * b.velocity.dot(b.velocity) + 0.5 * b.moment * b.angular_velocity ** 2
                   for b in world.bodies)

    e0 = energy()
    n_events = 0
    for _ in range(1000):
        n_events += len(world.step([(0.0, 0.0, 0.0)]))
    assert n_events > 20
    assert energy() == pytest.approx(e0, rel=1e-9)


@pytest.mark.parametrize("e", [0.0, 0.47, 1.0])
def test_wall_bounce_restitution(e):
    sc = two_body(e=e, robot_pos=(8.0, 5.0), robot_vel=(0.4, 0.1), object_pos=(2.0, 5.0),
                  control_period_s=0.01, substeps=1)
    world = World(sc)
    for _ in range(1000):
        events = world.step([(0.0, 0.0, 0.0)])
        if events or world.bodies[0].velocity.x != 0.4:
            break
    for _ in range(5):  # e = 0: the disc slides along the wall and stays in contact
        events += world.step([(0.0, 0.0, 0.0)])
    (event,) = events or world.flush_impacts()
    assert "wall" in (event.a, event.b)
    v_after = event.velocity_after("R1")
    assert v_after == pytest.approx((-e * 0.4, 0.1), abs=1e-9)


def test_thrust_is_clipped_and_in_body_frame():
    heading = math.pi / 3
    sc = two_body(robot_vel=(0.0, 0.0), heading=heading)
    core = TransportCore(sc)
    core.reset(np.random.default_rng(0))
    _, _, info = core.step([5.0, -5.0, 0.0])  # clipped to (+1, -1) of the limits
    fx, fy = 2.8, -2.8
    c, s = math.cos(heading), math.sin(heading)
    expected = np.array([c * fx - s * fy, s * fx + c * fy]) / 16.8 * 0.1
    body = core.world.bodies[0]
    assert np.array(body.velocity) == pytest.approx(expected, rel=1e-9)
    assert info["fuel_Ns"] == pytest.approx(math.hypot(fx, fy) * 0.1)


def test_torque_is_clipped():
    core = TransportCore(two_body(robot_vel=(0.0, 0.0)))
    core.reset(np.random.default_rng(0))
    core.step([0.0, 0.0, -3.0])
    assert core.world.bodies[0].angular_velocity == pytest.approx(-0.2 / 0.1594 * 0.1, rel=1e-9)


def test_thrust_noise_never_exceeds_limits():
    core = TransportCore(two_body(robot_vel=(0.0, 0.0)), thrust_noise=0.5)
    core.reset(np.random.default_rng(1))
    for _ in range(50):
        wrench = core.wrenches_from_action([1.0, -1.0, 1.0])[0]
        assert abs(wrench[0]) <= 2.8 and abs(wrench[1]) <= 2.8 and abs(wrench[2]) <= 0.2


def test_no_tunnelling_through_thin_obstacle_at_the_speed_the_check_allows():
    """A scenario passing the substep check cannot tunnel through a 2 cm obstacle."""
    from impact_env.transport.scenario import scenario_from_dict
    from tests.helpers import two_body_dict

    data = two_body_dict(robot_vel=(0.0, 0.0), object_pos=(8.0, 8.0))
    data["robots"][0]["velocity_bound_mps"] = [2.0, 2.0]
    data["obstacles"] = [{"name": "plate", "box": [5.0, 5.02, 0.0, 10.0]}]
    sc = scenario_from_dict(data)
    fastest = (1 + sc.restitution) * math.hypot(2.0, 2.0)
    world = World(sc)
    world.bodies[0].velocity = (fastest, 0.0)
    events = []
    for _ in range(10):  # 1 s: it reaches the plate after about 0.6 s
        events += world.step([(0.0, 0.0, 0.0)])
        assert world.bodies[0].position.x < 5.0
    assert world.bodies[0].velocity.x == pytest.approx(-0.75 * fastest)  # bounced back with e
    assert [e.b if e.a == "R1" else e.a for e in events] == ["plate"]


def test_fast_path_matches_public_api_bit_for_bit():
    """World.step's C-function fast path and pymunk's public API give identical trajectories."""
    from impact_env.transport.scenario import load_scenario

    sc = load_scenario("corridor")
    rng = np.random.default_rng(3)
    wrenches = [[tuple(w) for w in rng.uniform(-1, 1, (2, 3)) * [2.8, 2.8, 0.2]] for _ in range(300)]
    worlds = [World(sc, fast=True), World(sc, fast=False)]
    assert worlds[0]._fast is not None and worlds[1]._fast is None
    events = [[], []]
    for w in wrenches:
        for i, world in enumerate(worlds):
            events[i] += world.step(w)
        assert worlds[0].read_state() == worlds[1].read_state()
    assert [e.to_dict() for e in events[0]] == [e.to_dict() for e in events[1]]
    assert len(events[0]) > 0


def test_impact_velocity_noise_is_the_seeded_uniform_draw_on_top_of_eq5():
    """A robot-object impact: the object leaves with Eq. (5) plus exactly the generator's uniform draw; the
    robot's own velocity is Eq. (5) unchanged."""
    noise = 0.05
    sc = two_body(e=0.75, robot_vel=(0.3, 0.0), control_period_s=0.01, substeps=1)
    world = World(sc, impact_velocity_noise_mps=noise, rng=np.random.default_rng(7))
    event, _ = run_until_separated(world)
    vr, vo = eq5(16.8, 16.8, 0.3, 0.0, 0.75)
    draw = np.random.default_rng(7).uniform(-noise, noise, 2)
    assert event.velocity_after("O1") == pytest.approx((vo + draw[0], draw[1]), abs=1e-9)
    assert event.velocity_after("R1") == pytest.approx((vr, 0.0), abs=1e-9)
    assert tuple(world.bodies[1].velocity) == pytest.approx(event.velocity_after("O1"), abs=1e-12)


def test_impact_velocity_noise_is_uniform_within_its_bound():
    noise = 0.02
    errors = []
    for seed in range(300):
        sc = two_body(e=0.5, robot_vel=(0.3, 0.0), control_period_s=0.01, substeps=1)
        event, _ = run_until_separated(World(sc, impact_velocity_noise_mps=noise, rng=np.random.default_rng(seed)))
        errors.append(np.array(event.velocity_after("O1")) - (eq5(16.8, 16.8, 0.3, 0.0, 0.5)[1], 0.0))
    errors = np.array(errors)
    assert np.all(np.abs(errors) <= noise + 1e-12)
    # uniform on [-0.02, 0.02]: mean 0 (std of the mean 0.0007), standard deviation 0.02 / sqrt(3) = 0.0115
    assert np.all(np.abs(errors.mean(axis=0)) < 0.0025)
    np.testing.assert_allclose(errors.std(axis=0), noise / math.sqrt(3), rtol=0.12)


def test_impact_velocity_noise_leaves_wall_contacts_exact():
    sc = two_body(e=0.75, robot_pos=(2.0, 8.0), robot_vel=(0.0, 0.0), object_pos=(9.0, 5.0), object_vel=(0.4, 0.0),
                  control_period_s=0.01, substeps=1)
    world = World(sc, impact_velocity_noise_mps=0.05, rng=np.random.default_rng(0))
    for _ in range(1000):
        events = world.step([(0.0, 0.0, 0.0)])
        if events:
            break
    assert {events[0].a, events[0].b} == {"O1", "wall"}
    assert events[0].velocity_after("O1") == pytest.approx((-0.3, 0.0), abs=1e-9)


def test_impact_velocity_noise_option_in_the_env():
    from impact_env.envs import TransportEnv
    from impact_env.transport.core import EnvConfigError

    def first_impact(noise: float, seed: int):
        env = TransportEnv("throw_and_catch_exp", impact_velocity_noise_mps=noise)
        env.reset(seed=seed)
        push = np.zeros(env.action_space.shape)
        push[0] = 1.0  # R1 pushes straight at the object
        for _ in range(200):
            _, _, _, _, info = env.step(push)
            if info["impacts"]:
                return info["impacts"][0]
        raise AssertionError("no impact")

    base = first_impact(0.0, 0)
    assert first_impact(0.0, 5) == base  # no noise: the seed does not matter and no draw changes anything
    noisy = first_impact(0.03, 5)
    assert noisy == first_impact(0.03, 5)
    assert noisy != first_impact(0.03, 6)
    side = 0 if noisy["a"] == "O1" else 1
    key = "ab"[side] + "_velocity_after"
    error = np.subtract(noisy[key], base[key])
    assert 0 < np.max(np.abs(error)) <= 0.03
    for bad in (-0.1, 1.5, float("nan"), True):
        with pytest.raises(EnvConfigError, match=r"impact_velocity_noise_mps must be a finite number in \[0, 1\]"):
            TransportEnv("throw_and_catch_exp", impact_velocity_noise_mps=bad)
