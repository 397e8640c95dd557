"""The circular impact model (Eq. 6-7), its closed-form inverse checked in the simulator, and the replanner."""

from __future__ import annotations

import numpy as np
import pytest

from impact_env.physics import World
from planners.online.impact_model import disc_impact, required_contact
from planners.online.replanner import bounded_segment, hermite, replan_around_impact, replan_segment
from tests.helpers import two_body


@pytest.mark.parametrize("e,m_r,m_o", [(0.75, 16.8, 16.8), (0.47, 16.8, 8.0), (1.0, 5.0, 16.8)])
@pytest.mark.parametrize("v_o,v_des", [((0.0, 0.0), (0.1, 0.2)), ((0.1, -0.05), (-0.05, 0.15)),
                                       ((0.2, 0.0), (0.0, 0.0))])
def test_inverse_then_forward_gives_the_desired_velocity(e, m_r, m_o, v_o, v_des):
    c = required_contact((3.0, 4.0), v_o, v_des, m_r, 0.2, m_o, 0.25, e)
    np.testing.assert_allclose(np.linalg.norm(np.subtract((3.0, 4.0), c.robot_position)), 0.45)
    v_r_after, v_o_after = disc_impact(c.robot_position, c.robot_velocity_before, m_r, (3.0, 4.0), v_o, m_o, e)
    np.testing.assert_allclose(v_o_after, v_des, atol=1e-12)
    np.testing.assert_allclose(v_r_after, c.robot_velocity_after, atol=1e-12)
    assert (c.robot_velocity_before - np.asarray(v_o)) @ c.normal > 0  # the robot approaches


def test_no_impact_needed_returns_none():
    assert required_contact((0, 0), (0.1, 0.0), (0.1, 0.0), 1.0, 0.2, 1.0, 0.2, 0.5) is None


@pytest.mark.parametrize("v_o,v_des", [((0.0, 0.0), (0.12, 0.05)), ((0.05, -0.02), (-0.03, 0.1))])
def test_inverse_model_in_the_simulator(v_o, v_des):
    """A robot sent with the computed pre-impact state makes the object leave with the desired velocity."""
    e = 0.75
    c = required_contact((5.0, 5.0), v_o, v_des, 16.8, 0.2, 16.8, 0.2, e)
    # start both 2 s before contact on their straight approach paths, so they meet at the computed contact
    t_back = 2.0
    sc = two_body(e=e, robot_pos=tuple(c.robot_position - c.robot_velocity_before * t_back),
                  robot_vel=tuple(c.robot_velocity_before),
                  object_pos=tuple(np.array((5.0, 5.0)) - np.asarray(v_o) * t_back),
                  object_vel=v_o, control_period_s=0.01, substeps=1)
    world = World(sc)
    events = []
    for _ in range(400):
        events += world.step([(0.0, 0.0, 0.0)])
    hit = [ev for ev in events if {ev.a, ev.b} == {"R1", "O1"}]
    assert len(hit) == 1
    # contact is detected at the end of a substep, so the line of centres is off by under a substep of travel
    np.testing.assert_allclose(hit[0].velocity_after("O1"), v_des, atol=2e-3)
    np.testing.assert_allclose(hit[0].velocity_after("R1"), c.robot_velocity_after, atol=2e-3)


def test_hermite_meets_its_boundary_conditions():
    seg = hermite((0, 0), (0.1, 0.0), (1.0, 0.5), (0.0, -0.2), 2.0, 7.0)
    np.testing.assert_allclose(seg.position(2.0)[0], (0, 0))
    np.testing.assert_allclose(seg.position(7.0)[0], (1.0, 0.5))
    np.testing.assert_allclose(seg.velocity(2.0)[0], (0.1, 0.0))
    np.testing.assert_allclose(seg.velocity(7.0)[0], (0.0, -0.2), atol=1e-12)


def test_bounded_qp_equals_hermite_when_bounds_are_slack_and_respects_them_when_not():
    args = ((0, 0), (0.0, 0.0), (1.0, 0.0), (0.0, 0.0), 0.0, 10.0)
    free = hermite(*args)
    qp = bounded_segment(*args, velocity_bound=(1.0, 1.0))
    t = np.linspace(0, 10, 21)
    np.testing.assert_allclose(qp.position(t), free.position(t), atol=1e-4)
    # hermite peaks at 1.5 x the mean speed (0.15 m/s); a 0.14 m/s bound forces a flatter profile
    tight = replan_segment(*args, velocity_bound=(0.14, 0.14))
    assert np.abs(tight.velocity_control_points()).max() <= 0.14 + 1e-6
    np.testing.assert_allclose(tight.position(10.0)[0], (1.0, 0.0), atol=1e-6)


def test_replan_around_impact_joins_the_contact_and_the_plan():
    c = required_contact((2.0, 0.0), (0.0, 0.0), (0.2, 0.0), 16.8, 0.2, 16.8, 0.2, 0.5)
    pre, post = replan_around_impact(3.0, (0.5, 0.1), (0.0, 0.0), 8.0, c, 10.0, (1.4, 0.0), (0.0, 0.0))
    np.testing.assert_allclose(pre.position(8.0)[0], c.robot_position, atol=1e-12)
    np.testing.assert_allclose(pre.velocity(8.0)[0], c.robot_velocity_before, atol=1e-12)
    np.testing.assert_allclose(post.velocity(8.0)[0], c.robot_velocity_after, atol=1e-12)
    np.testing.assert_allclose(post.position(10.0)[0], (1.4, 0.0), atol=1e-12)
    with pytest.raises(ValueError):
        replan_around_impact(9.0, (0, 0), (0, 0), 8.0, c, 10.0, (0, 0), (0, 0))
