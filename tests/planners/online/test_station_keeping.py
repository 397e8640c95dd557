"""Station keeping (planners/online/station_keeping.py): a held goal's drift predicted in closed form, and the
trim the mission layer flies when the drift would leave the goal before its window ends.

The episodes are flown with ``ExpertConfig(aim_held_goal_center=False)``: the stops they trim were aimed at the
plan's rest point. Aimed at the held goal's middle (the default since), several of these drifts stay in the
goal and need no trim, so the trims these tests pin would not be asked for."""

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
    with pytest.raises(PlannerError, match="StationKeepingConfig.impact_robust"):
        StationKeepingConfig(impact_robust=1)


# ---------------------------------------------------------------------------------------------- closed loop
def _held_drift_episode(shipped_plans, seed: int, keeping, keep_settled: bool = True) -> bool:
    import dataclasses

    from impact_env.rollout import run_episode
    from impact_env.transport.gym_env import TransportEnv
    from planners.expert import Expert, ExpertConfig

    scenario = load_scenario("held_drift")
    config = ExpertConfig(aim_held_goal_center=False)  # the drifts measured (module docstring)
    if keeping != "default":
        config = dataclasses.replace(config, mission=dataclasses.replace(config.mission, station_keeping=keeping))
    config = dataclasses.replace(config, mission=dataclasses.replace(config.mission, keep_settled=keep_settled))
    expert = Expert(scenario, plan=shipped_plans.sr("held_drift"), config=config)
    return run_episode(TransportEnv(scenario, impact_velocity_noise_mps=0.02), expert, seed=seed).success


def test_station_keeping_holds_the_goal_in_closed_loop(shipped_plans):
    """held_drift under 0.02 m/s of post-impact noise (seeds of benchmarks/station_keeping.py's cells): without
    station keeping (and with the mission layer before keep_settled) the stopped object drifts out of the goal on
    seeds 2, 15 and 16, and the trims bring it back; with the earlier 0.05 m trigger margin, trims of a drift that
    stays in lose seed 8 (spatially robust trims, as measured), which the default (0 m) does not trim and holds.
    Seed 15 was lost to a mission re-plan of a drift that stayed in (its new impacts' noise): keep_settled alone
    holds it; and seed 8's trim at 0.05 m, planned impact-robust, tolerates its own noise."""
    assert StationKeepingConfig().margin_m == 0.0
    for seed in (2, 15, 16):
        assert not _held_drift_episode(shipped_plans, seed, None, keep_settled=False), seed
        assert _held_drift_episode(shipped_plans, seed, "default"), seed
    assert _held_drift_episode(shipped_plans, 15, None)
    assert not _held_drift_episode(shipped_plans, 8, StationKeepingConfig(margin_m=0.05, impact_robust=False))
    assert _held_drift_episode(shipped_plans, 8, "default")
    assert _held_drift_episode(shipped_plans, 8, StationKeepingConfig(margin_m=0.05))


def test_a_trim_infeasible_on_its_grid_is_tried_on_one_twice_as_fine(shipped_plans):
    """held_drift at 30 s: O1 at (2.4, 0) drifting at +0.01 m/s leaves the goal (x <= 2.45) at 35 s, before
    the window ends at 40 s. The trim's grid has two knots before that (2.5 s intervals: 4 over the 10 s left);
    when the planner finds no trim there, with or without end states, it is asked once more on 8 intervals."""
    from planners.online.station_keeping import StationKeeper

    scenario = load_scenario("held_drift")
    plan = shipped_plans.sr("held_drift")
    names = [b.name for b in scenario.bodies]
    index = {name: i for i, name in enumerate(names)}
    states = np.zeros((len(names), 6))
    states[index["O1"]] = [2.4, 0.0, 0.0, 0.01, 0.0, 0.0]
    states[index["R1"]] = [1.8, 0.0, 0.0, 0.0, 0.0, 0.0]
    states[index["R2"]] = [3.6, 0.0, 0.0, 0.0, 0.0, 0.0]
    trace = [states[:, :2].copy() for _ in range(301)]  # 0 to 30 s; O1 in the goal all along
    asked = []

    def solve(derived, t, pair, intervals, record, impact_robust):
        asked.append((intervals, derived.planner_intervals, derived.robots[0].final_position_m is None))
        return "kept: InfeasiblePlanError"

    keeper = StationKeeper(scenario, StationKeepingConfig(), solve, scenario.tf_s / scenario.planner_intervals)
    assert keeper.step(30.0, states, index, plan, set(range(len(plan.impacts))), trace, names,
                       lambda new, t, robots: []) is None
    assert asked == [(4, 4, False), (4, 4, True), (8, 8, False), (8, 8, True)]
    assert keeper.records[0].robot == "R1" and keeper.records[0].status == "kept: InfeasiblePlanError"


def test_timed_visits_seed_3_holds_its_goal_with_a_trim_flown_round_the_object():
    """timed_visits under 0.02 m/s of post-impact noise, seed 3 of the robustness benchmark (its plan): R1 stops
    O1 at 45 s, O1 drifts out of D before 60 s. The trim is infeasible on the 4 intervals of its grid and found on
    8; it asks R1 to get round O1 (it is below it), 5.32 s at least from its observed state in the 7.4 s there
    are, 1.39 times: refused with the planner's hand-over margin (0.5; the planner's own test of the way to a
    robot's first impact refuses it now, before the mission's side-switch test did), flown with the observed one
    (0.25, which the mission hands the planner for an approach from the observed state)."""
    import dataclasses

    from impact_env.rollout import run_episode
    from impact_env.transport.gym_env import TransportEnv
    from planners.expert import Expert, ExpertConfig
    from planners.plan import Plan
    from tests.paths import DATA

    scenario = load_scenario("timed_visits")
    plan = Plan.load(DATA / "plans" / "robustness" / "timed_visits.json")

    def fly(config):
        expert = Expert(scenario, plan=plan, config=config)
        result = run_episode(TransportEnv(scenario, impact_velocity_noise_mps=0.02), expert, seed=3)
        return result, expert.mission.station.records

    config = ExpertConfig(aim_held_goal_center=False)  # the drifts measured (module docstring)
    result, trims = fly(config)
    assert result.success and trims[0].status == "accepted" and trims[0].robot == "R1"
    planner_margin = dataclasses.replace(config, mission=dataclasses.replace(config.mission,
                                                                             observed_handover_margin=None))
    result, trims = fly(planner_margin)
    assert not result.success and trims[0].time_s == pytest.approx(45.1)
    assert trims[0].status == "kept: UnflyableHandoverError"


# ------------------------------------------------------------------------------- noise: trims and settled goals
def _timed_visits(seed: int, mission=None):
    """timed_visits under 0.02 m/s of post-impact noise, one seed of the robustness benchmark (its plan), flown
    with ``ExpertConfig()`` or with its mission config replaced; (result, trim records, mission report)."""
    import dataclasses

    from impact_env.rollout import run_episode
    from impact_env.transport.gym_env import TransportEnv
    from planners.expert import Expert, ExpertConfig
    from planners.plan import Plan
    from tests.paths import DATA

    scenario = load_scenario("timed_visits")
    config = ExpertConfig(aim_held_goal_center=False)  # the drifts measured (module docstring)
    if mission is not None:
        config = dataclasses.replace(config, mission=mission(config.mission))
    expert = Expert(scenario, plan=Plan.load(DATA / "plans" / "robustness" / "timed_visits.json"), config=config)
    result = run_episode(TransportEnv(scenario, impact_velocity_noise_mps=0.02), expert, seed=seed)
    return result, expert.mission.station.records, expert.report()["mission"]


def test_a_settled_success_is_not_re_planned():
    """timed_visits seed 0: R1's stop at 45 s, the last planned impact, leaves O1 drifting to 0.021 m of D's edge
    by 60 s: held, but below half the plan's 0.156 m. Re-planned anyway (keep_settled=False), the new impact's
    noise carries O1 out of D (station keeping cannot trim it back in time); kept, the free drift holds it."""
    import dataclasses

    result, trims, report = _timed_visits(0)
    assert result.success and report["attempts"] == 0 and report["settled"] > 0 and trims == []
    result, _, report = _timed_visits(0, lambda m: dataclasses.replace(m, keep_settled=False))
    assert not result.success and report["replans"] == 1


def test_a_trim_is_planned_to_tolerate_the_noise_of_its_own_impact():
    """timed_visits seed 4: the stop at 45 s leaves O1 drifting out of D. The impact-robust trim (on a 3-interval
    grid: its copy window fitted to it) tolerates 0.05 m/s per axis, more than the 0.02 m/s of the noise and the
    error the stop showed, and holds O1 in D whatever its own impact's noise. The spatially robust trim, the best
    trim were its impact exact, is carried out of D by its own noise before 60 s."""
    import dataclasses

    result, trims, _ = _timed_visits(4)
    assert result.success and trims[0].status == "accepted" and trims[0].planner == "ir"
    assert trims[0].delta_mps >= 0.02 > trims[0].observed_error_mps
    exact = StationKeepingConfig(impact_robust=False)
    result, trims, _ = _timed_visits(4, lambda m: dataclasses.replace(m, station_keeping=exact))
    assert not result.success and trims[0].status == "accepted" and trims[0].planner == "sr"
