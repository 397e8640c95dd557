"""Station keeping (planners/online/station_keeping.py): a held goal's drift predicted in closed form, and the
trim the mission layer flies when the drift would leave the goal before its window ends."""

from __future__ import annotations

import math

import numpy as np
import pytest

from impact_env.stl import parse
from impact_env.transport.scenario import load_scenario
from planners.errors import PlannerError
from planners.online.station_keeping import HeldGoal, StationKeepingConfig, drift_margin, held_goals


def test_held_goals_are_the_tasks_always_in_region_conjuncts():
    assert held_goals(load_scenario("held_drift").formula, {"O1"}) == [HeldGoal("O1", "goal", 20.0, 40.0)]
    formula = parse("F[0,10] in(O1, goal) & G[20,30] in(O2, goal) & G[5,6] !in(O1, goal)")
    assert held_goals(formula, {"O1", "O2"}) == [HeldGoal("O2", "goal", 20.0, 30.0)]
    assert held_goals(formula, {"O1"}) == []  # a robot's or another object's goal is not this object's


def test_drift_margin_is_the_free_flights_closest_approach_to_the_edge():
    """The goal [1.85, 2.45] x [-0.3, 0.3]: from its centre at 0.01 m/s along +x the object is 0.3 m from the
    right edge at 20 s and reaches it 30 s later; over a window ending at 40 s it keeps 0.1 m, ending at 60 s
    it leaves (its distance -0.1 m at 60 s) and is at a 0.05 m margin at 45 s, below it from the next
    sample on."""
    region = load_scenario("held_drift").region_map()["goal"]
    centre, v = np.array([2.15, 0.0]), np.array([0.01, 0.0])
    margin, at, leaves = drift_margin(HeldGoal("O1", "goal", 20.0, 40.0), region, 20.0, centre, v, 0.1, 0.05)
    assert margin == pytest.approx(0.1) and at == pytest.approx(40.0) and leaves == math.inf
    margin, at, leaves = drift_margin(HeldGoal("O1", "goal", 20.0, 60.0), region, 20.0, centre, v, 0.1, 0.05)
    assert margin == pytest.approx(-0.1) and at == pytest.approx(60.0) and leaves == pytest.approx(45.1)
    # observed before the window opens: the drift until it opens counts, the margin only over the window
    margin, at, _ = drift_margin(HeldGoal("O1", "goal", 20.0, 40.0), region, 10.0, centre - 10 * v, v, 0.1)
    assert margin == pytest.approx(0.1) and at == pytest.approx(40.0)
    # at rest it keeps its distance now
    margin, at, leaves = drift_margin(HeldGoal("O1", "goal", 20.0, 40.0), region, 25.0, centre, np.zeros(2), 0.1)
    assert margin == pytest.approx(0.3) and leaves == math.inf


def test_station_keeping_config_is_validated():
    with pytest.raises(PlannerError, match="StationKeepingConfig.margin_m"):
        StationKeepingConfig(margin_m=-0.1)
    with pytest.raises(PlannerError, match="StationKeepingConfig.max_trims"):
        StationKeepingConfig(max_trims=1.5)


# ---------------------------------------------------------------------------------------------- closed loop
def _held_drift_episode(shipped_plans, seed: int, keeping) -> bool:
    import dataclasses

    from impact_env.rollout import run_episode
    from impact_env.transport.gym_env import TransportEnv
    from planners.expert import Expert, ExpertConfig

    scenario = load_scenario("held_drift")
    config = ExpertConfig()
    if keeping != "default":
        config = dataclasses.replace(config, mission=dataclasses.replace(config.mission, station_keeping=keeping))
    expert = Expert(scenario, plan=shipped_plans.sr("held_drift"), config=config)
    return run_episode(TransportEnv(scenario, impact_velocity_noise_mps=0.02), expert, seed=seed).success


def test_station_keeping_holds_the_goal_in_closed_loop(shipped_plans):
    """held_drift under 0.02 m/s of post-impact noise (seeds of benchmarks/station_keeping.py's cells): without
    station keeping the stopped object drifts out of the goal on seeds 2, 15 and 16, and the trims bring it back;
    with the earlier 0.05 m trigger margin, trims of a drift that stays in lose seed 8, which the default (0 m)
    does not trim and holds."""
    assert StationKeepingConfig().margin_m == 0.0
    for seed in (2, 15, 16):
        assert not _held_drift_episode(shipped_plans, seed, None), seed
        assert _held_drift_episode(shipped_plans, seed, "default"), seed
    assert not _held_drift_episode(shipped_plans, 8, StationKeepingConfig(margin_m=0.05))
    assert _held_drift_episode(shipped_plans, 8, "default")
