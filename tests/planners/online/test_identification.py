"""Online identification of the impact model (planners/online/identification.py), in the simulator."""

from __future__ import annotations

import math

import pytest

import impact_env
from impact_env.transport.physics import World
from impact_env.transport.scenario import load_scenario
from planners.expert import Expert
from planners.online.identification import ImpactIdentifier
from tests.helpers import two_body

A_MAX = math.hypot(2.8, 2.8) / 16.8  # the largest acceleration of the test robots' thrust (m/s^2)


@pytest.mark.parametrize("true_e", [0.27, 0.67, 0.95])
@pytest.mark.parametrize("thrust_N", [0.0, 2.8])
def test_one_impact_identifies_a_mismatched_restitution_within_002(true_e, thrust_N):
    """The file says e = 0.47; the simulator uses true_e. One oblique impact, the robot thrusting through it."""
    scenario = two_body(e=0.47, robot_pos=(2.0, 5.0), robot_vel=(0.3, 0.05), object_pos=(3.0, 5.15),
                        object_vel=(-0.02, 0.0))
    world = World(scenario, restitution=true_e)
    events = []
    while not events:  # until the first contact has ended (a thrusting robot may push again later)
        events = [ev.to_dict() for ev in world.step([(thrust_N, 0.0, 0.0)])]
    assert [{ev["a"], ev["b"]} for ev in events] == [{"R1", "O1"}]
    ident = ImpactIdentifier(0.47, {"R1": 16.8, "O1": 16.8}, frozenset({"R1"}), frozenset({"O1"}),
                             accelerations={"R1": A_MAX})
    assert ident.restitution_for("R1", "O1") == 0.47  # the prior, before any impact
    ident.observe(events)
    assert abs(ident.restitution_for("R1", "O1") - true_e) < 0.02
    assert ident.estimate("R1", "O1").std < 0.02
    assert ident.mass_ratio("R1", "O1").mean == pytest.approx(1.0, abs=0.05)


def test_unobserved_pairs_use_the_pooled_estimate_and_contacts_with_walls_are_ignored():
    ident = ImpactIdentifier(0.5, {"R1": 16.8, "R2": 16.8, "O1": 16.8}, frozenset({"R1", "R2"}), frozenset({"O1"}),
                             accelerations={"R1": A_MAX, "R2": A_MAX})
    hit = {"time": 1.0, "a": "R1", "b": "O1", "a_velocity_before": [0.3, 0.0], "b_velocity_before": [0.0, 0.0],
           "a_velocity_after": [0.045, 0.0], "b_velocity_after": [0.255, 0.0], "duration": 0.01}  # e = 0.7
    wall = {**hit, "a": "R2", "b": "wall", "time": 3.0}
    assert len(ident.observe([wall, hit])) == 1
    assert ident.restitution_for("R1", "O1") == pytest.approx(0.7, abs=1e-3)
    assert ident.restitution_for("R2", "O1") == pytest.approx(0.7, abs=2e-3)  # pooled
    assert ident.estimate("R2", "O1").count == 1


def test_identification_through_the_pettingzoo_env(shipped_plans):
    """Each agent passes its own info; the estimate after the throw matches the simulator's restitution."""
    scenario = load_scenario("throw_and_catch_exp")
    expert = Expert(scenario, plan=shipped_plans.sr("throw_and_catch_exp"))
    true_e = scenario.restitution + 0.2
    par = impact_env.parallel_env(scenario="throw_and_catch_exp", restitution=true_e)
    observations, infos = par.reset(seed=0)
    expert.reset()
    seen = False
    while par.agents and not seen:
        actions = {a: expert.agent_action(a, observations[a], infos[a]) for a in par.agents}
        observations, _, _, _, infos = par.step(actions)
        seen = bool(expert.identifier.measurements)
    assert seen
    expert.agent_action("R1", observations["R1"], infos["R1"])  # the step's reports reach the estimator
    assert abs(expert.identifier.restitution_for("R1", "O1") - true_e) < 0.02
    assert abs(expert.report()["identification"]["restitution"]["pooled"]["mean"] - true_e) < 0.02
