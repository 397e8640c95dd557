"""The circular impact model (Eq. 6-7), its closed-form inverse checked in the simulator, and the replanner."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import casadi as ca
import numpy as np
import pytest

from impact_env.transport.physics import World
from planners.online.impact_model import disc_impact, required_contact
from planners.online.replanner import SegmentLimits, bounded_segment, hermite, replan_around_impact, replan_segment
from planners.online.segment_qp import _linspace, _qp
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


def _limited_problem(shift: float) -> tuple[tuple, dict]:
    """A segment that needs every kind of row: box, an obstacle face, another robot, acceleration bounds."""
    others = [lambda t: np.column_stack([0.5 + 0.0 * t, 0.1 + 0.02 * t])]
    limits = SegmentLimits(box=(-0.2, 1.3, -0.3, 0.6), half_planes=[(np.array([0.0, 1.0]), -0.25)],
                           others=others, separation_m=0.3)
    return ((0.0, shift), (0.05, 0.0), (1.0, 0.2), (0.0, 0.1), 0.0, 6.0), \
        {"velocity_bound": (0.4, 0.4), "limits": limits, "acceleration_bound": (0.2, 0.2)}


def test_bounded_qp_through_the_buffer_gives_the_numbers_of_a_plain_daqp_call():
    """bounded_segment writes the QP's numbers into arrays bound to DAQP once (the matrix in column-major
    order): the same numbers through the ordinary call must give the same control points to the last bit."""
    args, kwargs = _limited_problem(0.0)
    seg = bounded_segment(*args, **kwargs)
    assert seg is not None
    qp = _qp(10)
    buf = qp.buffers()
    assert np.isfinite(buf["lba"][2 * 10 + 18:]).sum() > 11  # half-plane and separation rows are on
    plain = qp.solver(h=ca.DM(qp.hess), g=buf["g"], a=ca.DM(buf["A"]), lba=buf["lba"], uba=buf["uba"],
                      lbx=buf["lbx"], ubx=buf["ubx"])
    x = plain["x"].full().ravel()
    np.testing.assert_array_equal(seg.control_points, np.column_stack([x[:11], x[11:]]))
    np.testing.assert_allclose(seg.position(0.0)[0], (0.0, 0.0), atol=1e-9)


def test_bounded_qp_from_several_threads_gives_each_its_own_answer():
    """One buffer per thread: concurrent calls neither share nor overwrite each other's numbers."""
    problems = [_limited_problem(shift) for shift in np.linspace(-0.05, 0.01, 12)]
    alone = [bounded_segment(*a, **k) for a, k in problems]
    assert all(seg is not None for seg in alone)
    with ThreadPoolExecutor(max_workers=4) as pool:
        together = list(pool.map(lambda p: bounded_segment(*p[0], **p[1]), problems * 5))
    for k, seg in enumerate(together):
        np.testing.assert_array_equal(seg.control_points, alone[k % len(problems)].control_points)


def test_linspace_is_numpys_to_the_last_bit():
    ramp = np.arange(11.0)
    rng = np.random.default_rng(3)
    for start, stop in [*rng.normal(size=(500, 2)) * 3.0, (0.7, 0.7), (0.0, 0.0), (-1e-300, 1e-300)]:
        np.testing.assert_array_equal(_linspace(np.float64(start), np.float64(stop), ramp),
                                      np.linspace(start, stop, 11))


def test_replan_around_impact_joins_the_contact_and_the_plan():
    c = required_contact((2.0, 0.0), (0.0, 0.0), (0.2, 0.0), 16.8, 0.2, 16.8, 0.2, 0.5)
    pre, post = replan_around_impact(3.0, (0.5, 0.1), (0.0, 0.0), 8.0, c, 10.0, (1.4, 0.0), (0.0, 0.0))
    np.testing.assert_allclose(pre.position(8.0)[0], c.robot_position, atol=1e-12)
    np.testing.assert_allclose(pre.velocity(8.0)[0], c.robot_velocity_before, atol=1e-12)
    np.testing.assert_allclose(post.velocity(8.0)[0], c.robot_velocity_after, atol=1e-12)
    np.testing.assert_allclose(post.position(10.0)[0], (1.4, 0.0), atol=1e-12)
    with pytest.raises(ValueError):
        replan_around_impact(9.0, (0, 0), (0, 0), 8.0, c, 10.0, (0, 0), (0, 0))
