"""Room for the disc robot behind an impact-robust plan's contacts (planners/offline/milp/contact_room.py).

The case: throw_and_catch_exp with the far wall moved in to x = 3.3 (R2 parked at x = 3.05). R2 stops the
object at its goal (x = 2.5) from the wall's side; a catch box of half-width h puts R2's centre at
2.5 + h + 0.4, which must stay <= 3.1 (the wall less R2's radius): h <= 0.2 m, where the point-contact
planner spends 0.3 m.
"""

from __future__ import annotations

import math
from importlib import resources

import numpy as np
import pytest
import tomllib

from impact_env.transport.scenario import scenario_from_dict
from planners.errors import PlannerError
from planners.offline.guarantee import contact_room, rollout, worst_case_errors
from planners.offline.impact_robust import IRPlannerConfig, plan_impact_robust
from planners.offline.milp.contact_room import cone_extremes


def near_wall():
    data = tomllib.loads(resources.files("impact_env.transport.scenarios").joinpath("throw_and_catch_exp.toml")
                         .read_text())
    data["world"]["box"] = [0.0, 3.3, -1.5, 1.5]
    data["robots"][1]["position_m"] = data["robots"][1]["final_position_m"] = [3.05, 0.0]
    return scenario_from_dict(data)


def near_obstacle():
    """The same, with the wall at x = 3.3 an obstacle instead (a post from x = 3.3 to 3.6 the world's height)."""
    data = tomllib.loads(resources.files("impact_env.transport.scenarios").joinpath("throw_and_catch_exp.toml")
                         .read_text())
    data["obstacles"] = [{"name": "post", "box": [3.3, 3.6, -1.5, 1.5]}]
    data["robots"][1]["position_m"] = data["robots"][1]["final_position_m"] = [3.05, 0.0]
    return scenario_from_dict(data)


@pytest.fixture(scope="module")
def plans():
    scenario = near_wall()
    return scenario, {cones: plan_impact_robust(scenario, IRPlannerConfig(contact_cones=cones)) for cones in (None, 8)}


def samples(plan, n: int = 300):
    d = plan.delta_mps
    rng = np.random.default_rng(0)
    return [rng.uniform(-d, d, (len(plan.impacts), 2)) for _ in range(n)] + worst_case_errors(plan)


def test_point_contacts_leave_no_room_for_the_disc_behind_the_catch(plans):
    """Without the rows the catch box is as wide as before and, with errors within delta, R2's centre would
    have to be up to 0.1 m beyond the wall."""
    scenario, by_cones = plans
    plan = by_cones[None]
    outcomes = [rollout(plan, scenario, e) for e in samples(plan)]
    assert min(o.contact_room_m for o in outcomes) < -0.05
    assert not all(o.ok for o in outcomes)


def test_the_disc_has_room_behind_every_contact_for_errors_up_to_delta(plans):
    """With the rows (the default): 300 random errors in [-delta, delta]^2 at every impact and every vertex of
    that set keep the task, the boxes, the final box and the room; the room binds (the catch box is as wide
    as the wall allows), and delta is smaller than the point-contact plan's but > 0."""
    scenario, by_cones = plans
    plan = by_cones[8]
    assert 0.0 < plan.delta_mps < by_cones[None].delta_mps
    outcomes = [rollout(plan, scenario, e) for e in samples(plan)]
    assert all(o.ok for o in outcomes)
    assert min(o.contact_room_m for o in outcomes) == pytest.approx(0.0, abs=0.02)
    plan.check(scenario, tol=1e-6)


def test_the_disc_has_room_behind_every_contact_in_front_of_an_obstacle_too():
    """An obstacle behind the catch binds as the wall did: without the obstacle rows the catch box is the
    point-contact one, and R2's centre would have to be up to 0.1 m inside the post."""
    scenario = near_obstacle()
    plan = plan_impact_robust(scenario, IRPlannerConfig())
    outcomes = [rollout(plan, scenario, e) for e in samples(plan)]
    assert all(o.ok for o in outcomes)
    assert min(o.contact_room_m for o in outcomes) == pytest.approx(0.0, abs=0.02)
    # the point contact at the catch box's far side: 0.1 m into the post (grown by R2's radius)
    assert contact_room(scenario, "R2", "O1", np.array([2.8, 0.0]), np.array([-0.1, 0.0])) == pytest.approx(-0.1)


def test_contact_room_is_the_disc_centre_inside_the_shrunk_world():
    scenario = near_wall()  # x in [0, 3.3], radii 0.2: the robot's centre in [0.2, 3.1]
    # pushed toward +x at x = 2.6: the robot is at 2.2, 0.9 m from 3.1 (2.0 from 0.2, 1.3 from the y sides)
    assert contact_room(scenario, "R2", "O1", np.array([2.6, 0.0]), np.array([0.1, 0.0])) == pytest.approx(0.9)
    # pushed toward -x at x = 2.8: the robot would be at 3.2, 0.1 m beyond 3.1
    assert contact_room(scenario, "R2", "O1", np.array([2.8, 0.0]), np.array([-0.1, 0.0])) == pytest.approx(-0.1)
    assert contact_room(scenario, "R2", "O1", np.array([2.8, 0.0]), np.zeros(2)) == math.inf


@pytest.mark.parametrize("cones", [4, 8, 16])
def test_cone_extremes_hold_every_direction_of_their_cone(cones):
    """Cone m spans the angles within 2 pi / cones of 2 pi m / cones; its extremes bound n over all of them
    and are reached."""
    extremes = cone_extremes(cones)
    step = 2 * np.pi / cones
    for m, ((x_lo, x_hi), (y_lo, y_hi)) in enumerate(extremes):
        theta = np.linspace(m * step - step, m * step + step, 401)
        n_x, n_y = np.cos(theta), np.sin(theta)
        assert np.all((x_lo - 1e-12 <= n_x) & (n_x <= x_hi + 1e-12) & (y_lo - 1e-12 <= n_y) & (n_y <= y_hi + 1e-12))
        assert (n_x.min(), n_x.max(), n_y.min(), n_y.max()) == pytest.approx((x_lo, x_hi, y_lo, y_hi), abs=1e-4)


def test_contact_cones_is_checked():
    with pytest.raises(PlannerError, match="contact_cones"):
        IRPlannerConfig(contact_cones=3)
