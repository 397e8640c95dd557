"""The replanner's bounded segment keeps its fixed end states, and the closed-form feasibility test of its
bounds (planners/online/segment_feasibility.py) agrees with an LP solver."""

from __future__ import annotations

import numpy as np
import pytest

from planners import bezier
from planners.errors import ReplanInputError
from planners.online import replanner
from planners.online.replanner import DEGREE, SegmentLimits, bounded_segment, replan_segment, within_bounds
from planners.online.segment_feasibility import bounds_feasible, least_acceleration_bound, velocity_sum_range
from planners.online.segment_qp import _qp

# A relay approach (ExpertConfig(), combined condition: e +-0.2, 10 cm start offset, 10 % thrust noise, seed 1,
# robot R3 at t = 23.4 s on its way to a contact with O1 at t = 25 s): the robot flies away from the contact at
# 0.13 m/s along x and must turn around and arrive at 0.18 m/s within 1.6 s, which the thrust limit
# (0.133 m/s^2 per axis) cannot do. DAQP reported success on this QP and answered a segment that ends 5.3 cm
# off the contact at 0.155 m/s instead of 0.203 m/s; the replanner used to accept it.
RELAY_CASE = dict(p0=(2.838646173477173, 0.7608340978622437), v0=(-0.1349058747291565, 0.07458680123090744),
                  p1=(2.8181974443749906, 0.9113698541532624), v1=(0.18387282869313562, 0.085033461397817),
                  t0=23.400000000000002, t1=25.0)
RELAY_BOUNDS = dict(velocity_bound=(0.3, 0.3), acceleration_bound=(0.1333333333333333, 0.1333333333333333))
RELAY_BOX = (0.2, 5.8, 0.2, 4.8)


def _args(case: dict) -> tuple:
    return case["p0"], case["v0"], case["p1"], case["v1"], case["t0"], case["t1"]


def _lp_feasible(p0, v0, p1, v1, duration_s, degree, velocity_bound, acceleration_bound) -> bool:
    """The QP's constraints (without limits) as an LP over the control points of both axes, rows built from
    the Bezier derivative (planners.bezier), solved by HiGHS through scipy."""
    from scipy.optimize import linprog

    n = degree + 1
    first = bezier.derivative(np.eye(n)) / duration_s  # velocity control points = first @ P
    second = bezier.derivative(bezier.derivative(np.eye(n))) / duration_s ** 2
    rows, upper = [], []
    for axis in range(2):
        for matrix, bound in ((first, velocity_bound), (second, acceleration_bound)):
            if bound is None:
                continue
            block = np.zeros((len(matrix), 2 * n))
            block[:, axis * n:(axis + 1) * n] = matrix
            rows += [block, -block]
            upper += [np.full(2 * len(matrix), float(bound[axis]))]
    bounds = [(None, None)] * (2 * n)
    for axis in range(2):
        fixed = (p0[axis], p0[axis] + v0[axis] * duration_s / degree, p1[axis] - v1[axis] * duration_s / degree,
                 p1[axis])
        for index, value in zip((0, 1, n - 2, n - 1), fixed):
            bounds[axis * n + index] = (value, value)
    result = linprog(np.zeros(2 * n), A_ub=np.vstack(rows) if rows else None,
                     b_ub=np.concatenate(upper) if upper else None, bounds=bounds, method="highs")
    assert result.status in (0, 2), result.message  # solved or proven infeasible
    return result.status == 0


def _ends(segment, case: dict) -> tuple[float, float]:
    """How far the segment's end position (m) and end velocity (m/s) are from the asked ones."""
    end = segment.position(case["t1"])[0]
    return float(np.hypot(*(end - case["p1"]))), float(np.hypot(*(segment.velocity(case["t1"])[0] - case["v1"])))


def test_an_infeasible_qp_that_daqp_calls_solved_gives_no_segment_and_the_replanner_keeps_the_contact():
    duration = RELAY_CASE["t1"] - RELAY_CASE["t0"]
    problem = (RELAY_CASE["p0"], RELAY_CASE["v0"], RELAY_CASE["p1"], RELAY_CASE["v1"], duration, DEGREE)
    assert not _lp_feasible(*problem, **RELAY_BOUNDS)  # no segment can meet the end states and the bounds
    assert not bounds_feasible(*problem, **RELAY_BOUNDS)
    limits = SegmentLimits(box=RELAY_BOX)
    seg = bounded_segment(*_args(RELAY_CASE), limits=limits, **RELAY_BOUNDS)
    # a QP answer is a segment only if it keeps the fixed end states (it used to end 5.3 cm off the contact)
    assert seg is None or max(_ends(seg, RELAY_CASE)) < 1e-8
    replanned = replan_segment(*_args(RELAY_CASE), limits=limits, **RELAY_BOUNDS)
    position_error, velocity_error = _ends(replanned, RELAY_CASE)
    assert position_error < 1e-9 and velocity_error < 1e-9
    np.testing.assert_allclose(replanned.position(RELAY_CASE["t0"])[0], RELAY_CASE["p0"], atol=1e-12)
    assert within_bounds(replanned, RELAY_BOUNDS["velocity_bound"])  # the velocity bound can be met, and is


def test_replan_segment_raises_the_acceleration_bound_to_the_least_that_meets_the_contact(monkeypatch):
    """Infeasible under the thrust limit (the closed form says so before any QP): the QPs get the least
    acceleration bound that joins the end states instead, on the axis that needs it."""
    calls = []
    real = replanner.bounded_segment

    def counting(*args, **kwargs):
        calls.append(kwargs.get("acceleration_bound"))
        return real(*args, **kwargs)

    monkeypatch.setattr(replanner, "bounded_segment", counting)
    duration = RELAY_CASE["t1"] - RELAY_CASE["t0"]
    least = least_acceleration_bound(RELAY_CASE["p0"], RELAY_CASE["v0"], RELAY_CASE["p1"], RELAY_CASE["v1"],
                                     duration, DEGREE, **RELAY_BOUNDS)
    assert least[0] > 1.9 * RELAY_BOUNDS["acceleration_bound"][0]  # x must turn around: about 0.26 m/s^2
    assert least[1] == RELAY_BOUNDS["acceleration_bound"][1]  # y can be flown
    seg = replan_segment(*_args(RELAY_CASE), limits=SegmentLimits(box=RELAY_BOX), **RELAY_BOUNDS)
    assert len(calls) == 1  # one QP, with the limits and the raised bound: the two flyable ones are skipped
    raised = np.asarray(calls[0])
    np.testing.assert_allclose(raised, (least[0] * (1 + replanner.RAISED_MARGIN) + 1e-6, least[1]))
    assert within_bounds(seg, RELAY_BOUNDS["velocity_bound"], raised + 1e-6)
    peak = np.abs(seg.acceleration_control_points()).max(axis=0)
    assert peak[0] > least[0] * (1 - 1e-6)  # no segment asks for less
    assert max(_ends(seg, RELAY_CASE)) < 1e-8
    calls.clear()
    # 2 s more make the turn flyable (not by the Hermite cubic): the QP with the limits and the thrust limit
    slow = dict(RELAY_CASE, t1=RELAY_CASE["t1"] + 2.0)
    seg = replan_segment(*_args(slow), limits=SegmentLimits(box=RELAY_BOX), **RELAY_BOUNDS)
    assert calls == [RELAY_BOUNDS["acceleration_bound"]]
    assert within_bounds(seg, RELAY_BOUNDS["velocity_bound"], np.add(RELAY_BOUNDS["acceleration_bound"], 1e-6))
    assert max(_ends(seg, slow)) < 1e-8


def test_answer_holds_rejects_a_moved_fixed_point_and_keeps_a_solved_one():
    case = dict(RELAY_CASE, t1=RELAY_CASE["t1"] + 2.0)
    assert bounded_segment(*_args(case), limits=SegmentLimits(box=RELAY_BOX), **RELAY_BOUNDS) is not None
    qp = _qp(DEGREE)
    buf = qp.buffers()
    assert qp.answer_holds()
    x = buf["x"]
    kept = x.copy()
    for index in qp.fixed:
        x[index] += 1e-7  # the least a DAQP answer to an infeasible QP moved a fixed point by was 1e-6 m
        assert not qp.answer_holds()
        x[:] = kept
    x[qp.fixed[1]] += 1e-11  # rounding of a solved QP (1e-11 m at most, measured)
    assert qp.answer_holds()
    x[:] = kept


def test_bounds_feasible_on_closed_forms():
    # rest to rest over 1 m in 10 s: the fastest profile's velocity control points sum to the run
    assert bounds_feasible((0, 0), (0, 0), (1, 0), (0, 0), 10.0, 10, (1.0, 1.0), (0.1, 0.1))
    # reversing 0.2 m/s is 0.4 m/s of velocity change: 4 s at 0.1 m/s^2 at the least, 3.9 s are not enough;
    # in 4 s the only profile is the linear ramp, whose control points sum to 0: it ends where it started
    assert bounds_feasible((0, 0), (0.2, 0), (0, 0), (-0.2, 0), 4.0, 10, None, (0.1, 0.1))
    assert not bounds_feasible((0, 0), (0.2, 0), (0.01, 0), (-0.2, 0), 4.0, 10, None, (0.1, 0.1))
    assert not bounds_feasible((0, 0), (0.2, 0), (0, 0), (-0.2, 0), 3.9, 10, None, (0.1, 0.1))
    # end velocities beyond the velocity bound cannot be kept
    assert not bounds_feasible((0, 0), (0.31, 0), (1, 0), (0, 0), 10.0, 10, (0.3, 0.3), None)
    # no bounds: every end state can be joined
    assert bounds_feasible((0, 0), (5, -5), (-3, 8), (2, 2), 0.1, 10)
    # the widest sums: with only a velocity bound, the interior points reach it
    low, high = velocity_sum_range((0.1, 0), (0, 0), 1.0, 10, (0.3, 0.3))
    np.testing.assert_allclose(high, (0.1 + 8 * 0.3, 8 * 0.3))
    np.testing.assert_allclose(low, (0.1 - 8 * 0.3, -8 * 0.3))


@pytest.mark.parametrize("bad", [dict(duration_s=0.0), dict(duration_s=-1.0), dict(degree=2),
                                 dict(velocity_bound=(-0.1, 0.3)), dict(acceleration_bound=(0.1, -1e-3))])
def test_bounds_feasible_rejects_bad_input_naming_the_field(bad):
    kwargs = dict(duration_s=1.0, degree=10, velocity_bound=(0.3, 0.3), acceleration_bound=(0.1, 0.1)) | bad
    with pytest.raises(ReplanInputError, match=next(iter(bad))):
        bounds_feasible((0, 0), (0, 0), (1, 0), (0, 0), **kwargs)


def segment_problems():
    """(p0, v0, p1, v1, duration_s, degree), velocity_bound, acceleration_bound: end velocities as fractions
    of the bound (a few beyond it), the acceleration bound a multiple of the least that joins them (a few
    below), the run such that the mean velocity falls from 15 % below to 15 % above the range the closed form
    gives (its ends too). About half the cases are feasible, many on the boundary; the LP is the judge. A
    hypothesis strategy, built when a test draws from it (hypothesis is not imported to collect the suite)."""
    from hypothesis import strategies as st

    @st.composite
    def problems(draw) -> tuple:
        fraction, pair = st.floats(-1.02, 1.02), st.tuples
        duration_s = draw(st.floats(0.1, 12.0))
        degree = draw(st.sampled_from([3, 4, 10]))
        velocity_bound = draw(st.one_of(st.none(), pair(st.floats(0.05, 0.5), st.floats(0.05, 0.5))))
        scale = np.full(2, 0.3) if velocity_bound is None else np.asarray(velocity_bound)
        v0 = np.asarray(draw(pair(fraction, fraction))) * scale
        v1 = np.asarray(draw(pair(fraction, fraction))) * scale
        turn = np.asarray(draw(pair(st.floats(0.9, 4.0), st.floats(0.9, 4.0))))
        acceleration_bound = tuple(turn * np.abs(v1 - v0) / duration_s + 1e-4) if draw(st.booleans()) else None
        low, high = velocity_sum_range(v0, v1, duration_s, degree, velocity_bound, acceleration_bound)
        low, high = np.where(np.isfinite(low), low, -degree * 0.5), np.where(np.isfinite(high), high, degree * 0.5)
        where = st.one_of(st.floats(-0.15, 1.15), st.sampled_from([0.0, 1.0]))
        p0 = np.array([0.4, -0.2])
        p1 = p0 + (low + np.asarray(draw(pair(where, where))) * (high - low)) * duration_s / degree
        return (p0, v0, p1, v1, duration_s, degree), velocity_bound, acceleration_bound

    return problems()


def _shifted(bound, delta: float, relative: float = 0.0):
    return None if bound is None else tuple(max(b * (1 + relative) + delta, 0.0) for b in bound)


def test_bounds_feasible_agrees_with_an_lp_solver():
    """Sound: a False is never given to a feasible problem. Exact: it agrees with HiGHS wherever HiGHS's
    verdict is robust (the same with the bounds 1e-6 tighter and 1e-6 looser)."""
    from hypothesis import event, given, settings

    @settings(max_examples=300, deadline=None)
    @given(case=segment_problems())
    def check(case):
        problem, velocity_bound, acceleration_bound = case
        if not bounds_feasible(*problem, velocity_bound, acceleration_bound):
            event("infeasible")
            assert not _lp_feasible(*problem, velocity_bound, acceleration_bound)
        else:
            event("feasible")
        tight = _lp_feasible(*problem, _shifted(velocity_bound, -1e-6), _shifted(acceleration_bound, -1e-6))
        loose = _lp_feasible(*problem, _shifted(velocity_bound, 1e-6), _shifted(acceleration_bound, 1e-6))
        if tight == loose:
            assert bounds_feasible(*problem, velocity_bound, acceleration_bound, tol=0.0) == tight

    check()


def test_least_acceleration_bound_is_the_least_that_an_lp_solver_finds_feasible():
    from hypothesis import event, given, settings

    @settings(max_examples=150, deadline=None)
    @given(case=segment_problems())
    def check(case):
        problem, velocity_bound, acceleration_bound = case
        given_bound = (0.1, 0.1) if acceleration_bound is None else acceleration_bound
        least = least_acceleration_bound(*problem, velocity_bound, given_bound, tol=0.0)
        event("velocity bound unmet" if least is None else "raised" if (least > given_bound).any() else "as given")
        if least is None:  # only when the velocity bound cannot be met, whatever the thrust (or by 1e-6 at most)
            assert not _lp_feasible(*problem, _shifted(velocity_bound, -1e-6), None)
            return
        assert (least >= np.asarray(given_bound)).all()
        assert _lp_feasible(*problem, velocity_bound, _shifted(least, 1e-7, 1e-5))
        for axis in range(2):
            if least[axis] > given_bound[axis] * (1 + 1e-4) + 1e-6:  # raised: a little less is not enough
                lower = least.copy()
                lower[axis] = least[axis] * (1 - 1e-4) - 1e-6
                assert not _lp_feasible(*problem, velocity_bound, tuple(lower))

    check()
