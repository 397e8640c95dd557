"""The time-optimal refinement with k robots (CasADi)."""

from __future__ import annotations

import numpy as np
import pytest

from impact_env.tether.station import load_station
from planners.errors import PlannerError
from planners.tether.reachability import plan_reachability
from planners.tether.timing import refine_timing


@pytest.fixture(scope="module")
def l_plan():
    st = load_station("L")
    return st, plan_reachability(st)


def test_one_robot_cannot_beat_the_plan_at_full_speed(l_plan):
    st, plan = l_plan
    r = refine_timing(st, plan, k=1, nodes=12)
    assert r.status == "optimal"
    # one unit of pull moves the cargo at most at w: the plan's straight pulls are (nearly) optimal; the
    # corridors only let the switch points slide a little
    assert 0.9 * r.plan_s <= r.total_s <= r.plan_s + 1e-6
    assert r.bang_bang_fraction > 0.9


def test_more_robots_are_faster_and_the_schedule_is_consistent(l_plan):
    st, plan = l_plan
    r1, r2 = refine_timing(st, plan, k=1, nodes=12), refine_timing(st, plan, k=2, nodes=12)
    assert r2.status == "optimal" and r2.total_s < 0.75 * r1.total_s
    assert 0.0 <= r2.bang_bang_fraction <= 1.0
    for U in r2.activations:
        assert U.min() >= -1e-6 and U.max() <= 1 + 1e-6 and U.sum(axis=1).max() <= 2 + 1e-6
    # replay the activations through Eq. 5 (the physics module's RK4): the cargo ends in the goal box
    x = np.asarray(plan.start_m)
    for T, anchors, U, X in zip(r2.durations_s, r2.anchors, r2.activations, r2.states):
        h = T / len(U)
        for u in U:
            # Eq. 5 with activations: each anchor's unit vector weighted by u, i.e. w scaled per anchor
            pos = st.anchor_positions[anchors]
            vel = lambda p, pos=pos, u=u: st.pull_speed_mps * sum(  # noqa: E731
                ui * (a - p) / np.linalg.norm(a - p) for ui, a in zip(u, pos))
            k1 = vel(x)
            k2 = vel(x + 0.5 * h * k1)
            k3 = vel(x + 0.5 * h * k2)
            k4 = vel(x + h * k3)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            assert st.cargo_inside(x, tol_m=1e-3)
        np.testing.assert_allclose(x, X[-1], atol=1e-5)
    x0, x1, y0, y1 = st.goal_box
    assert x0 <= x[0] <= x1 and y0 <= x[1] <= y1


def test_bad_k_is_a_typed_error(l_plan):
    st, plan = l_plan
    with pytest.raises(PlannerError, match="k must be >= 1"):
        refine_timing(st, plan, k=0)
