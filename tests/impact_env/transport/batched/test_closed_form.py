"""Closed-form physics against both backends, the pymunk world and the batched world (float64): the paper's
Eq. 5 (head-on) and Eq. 6-7 (oblique) at mass ratios 1 and 10, momentum, a wall bounce, and energy with e = 1."""

from __future__ import annotations

import numpy as np
import pytest

from impact_env.transport.scenario import scenario_from_dict
from tests.helpers import modified, two_body_dict
from tests.impact_env.transport.batched.backends import BACKENDS, make_backend


def eq5(m_r: float, m_o: float, v_r: float, v_o: float, e: float) -> tuple[float, float]:
    """Eq. (5): post-impact normal velocities of a robot and an object."""
    s = m_r + m_o
    return ((m_r - e * m_o) / s * v_r + (1 + e) * m_o / s * v_o,
            (1 + e) * m_r / s * v_r + (m_o - e * m_r) / s * v_o)


def scenario(horizon_s: float = 10.0, **kwargs):
    data = two_body_dict(**kwargs)
    data = modified(data, "tf_s", horizon_s)
    return scenario_from_dict(modified(data, "task", f"F[0,{horizon_s:g}] in(O1, goal)"))


def until_separated(backend, max_steps: int = 3000):
    """Step without thrust until the first contact ends (or, e = 0, 20 steps after touching); returns the
    state then and the line of centres at first touch (pymunk detects at the positions advanced by one step)."""
    normal = None
    since = 0
    for _ in range(max_steps):
        s = backend.state()
        ahead = s[:, :2] + s[:, 2:4] * backend.dt_s
        ended = backend.step()
        if normal is None and (backend.touching() or ended):
            d = ahead[1] - ahead[0]
            normal = d / np.linalg.norm(d)
        if ended:
            return backend.state(), normal
        if normal is not None:
            since += 1
            if since > 20:
                return backend.state(), normal
    raise AssertionError("no impact happened")


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("e", [0.0, 0.47, 0.75, 1.0])
@pytest.mark.parametrize("m_r,m_o", [(16.8, 16.8), (16.8, 1.68), (1.68, 16.8)])
def test_head_on_matches_eq5(backend, e, m_r, m_o):
    sc = scenario(e=e, m_robot=m_r, m_object=m_o, robot_vel=(0.3, 0.0), object_vel=(-0.1, 0.0),
                  control_period_s=0.01, substeps=1)
    state, _ = until_separated(make_backend(backend, sc))
    vr, vo = eq5(m_r, m_o, 0.3, -0.1, e)
    np.testing.assert_allclose(state[0, 2:4], (vr, 0.0), atol=1e-9)
    np.testing.assert_allclose(state[1, 2:4], (vo, 0.0), atol=1e-9)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("e", [0.3, 0.75, 1.0])
@pytest.mark.parametrize("m_r,m_o,offset", [(16.8, 16.8, 0.15), (16.8, 1.68, -0.05), (1.68, 16.8, 0.3)])
def test_oblique_impact_matches_eq6_7(backend, e, m_r, m_o, offset):
    sc = scenario(e=e, m_robot=m_r, m_object=m_o, robot_vel=(0.25, 0.05), object_vel=(-0.05, 0.0),
                  object_pos=(4.0, 5.0 + offset), control_period_s=0.01, substeps=1)
    state, n = until_separated(make_backend(backend, sc))
    vr0, vo0 = np.array([0.25, 0.05]), np.array([-0.05, 0.0])
    t = np.array([-n[1], n[0]])
    vr_n, vo_n = eq5(m_r, m_o, vr0 @ n, vo0 @ n, e)
    np.testing.assert_allclose(state[0, 2:4], vr_n * n + (vr0 @ t) * t, atol=1e-9)  # Eq. (7)
    np.testing.assert_allclose(state[1, 2:4], vo_n * n + (vo0 @ t) * t, atol=1e-9)
    np.testing.assert_allclose(state[:, 5], 0.0, atol=1e-12)  # frictionless, through the centres: no spin


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("m_o", [16.8, 1.68])
def test_momentum_is_conserved(backend, m_o):
    sc = scenario(e=0.6, m_object=m_o, robot_vel=(0.3, 0.1), object_vel=(-0.1, 0.02), object_pos=(4.0, 5.2))
    b = make_backend(backend, sc)
    masses = np.array([16.8, m_o])[:, None]
    p0 = (masses * b.state()[:, 2:4]).sum(0)
    events = sum(b.step() for _ in range(60))
    p1 = (masses * b.state()[:, 2:4]).sum(0)
    assert events == 1  # they collided once, far from the walls
    np.testing.assert_allclose(p1, p0, atol=1e-12)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("e", [0.0, 0.47, 1.0])
def test_wall_bounce_restitution(backend, e):
    sc = scenario(e=e, robot_pos=(8.0, 5.0), robot_vel=(0.4, 0.1), object_pos=(2.0, 5.0),
                  control_period_s=0.01, substeps=1)
    b = make_backend(backend, sc)
    for _ in range(2000):
        ended = b.step()
        if ended or b.state()[0, 2] != 0.4:
            break
    for _ in range(5):  # e = 0: the disc slides along the wall and stays in contact
        b.step()
    np.testing.assert_allclose(b.state()[0, 2:4], (-e * 0.4, 0.1), atol=1e-9)


@pytest.mark.parametrize("backend", BACKENDS)
def test_energy_is_conserved_with_e_1(backend):
    """e = 1: 100 s of bouncing between two discs and the four walls keeps the kinetic energy."""
    sc = scenario(horizon_s=100.0, e=1.0, robot_pos=(2.0, 3.0), robot_vel=(0.9, 0.4), object_pos=(3.0, 6.0),
                  object_vel=(-0.5, 0.7), box=(0.0, 4.0, 0.0, 8.0))
    b = make_backend(backend, sc)
    masses = np.array([16.8, 16.8])

    def energy() -> float:
        s = b.state()
        return float((0.5 * masses * (s[:, 2] ** 2 + s[:, 3] ** 2)).sum())

    e0 = energy()
    events = sum(b.step() for _ in range(1000))
    assert events > 20
    assert energy() == pytest.approx(e0, rel=1e-9)
