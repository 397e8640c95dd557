"""The solver's thread count is pinned wherever the same input must give the same plan on any machine.

HiGHS left to choose (``threads=None``) takes a thread count from the machine's cores, and the count can
change a MILP's last bits; mission re-plans (planners/online/mission.py) and the jobs of a planned list of
scenarios (planners/offline/batch.py) therefore pin it.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import planners.online.mission as mission
from impact_env.transport.scenario import load_scenario
from planners.errors import PlannerError
from planners.offline.batch import plan_scenarios
from planners.offline.spatially_robust import PlannerConfig
from planners.online.bookkeeping import ImpactBook
from planners.online.mission import MissionConfig, MissionPlanner
from planners.plan import Plan
from tests.paths import DATA

CASE = DATA / "two_objects_replan_at_10s.json"


@pytest.mark.parametrize("threads", [0, -1, 1.5, True, None])
def test_mission_threads_must_be_a_positive_integer(threads):
    with pytest.raises(PlannerError, match=r"(MissionConfig\.solver_options|SolverOptions)\.threads must be "
                                            r"(None \(the solver chooses\) or )?an integer >= 1"):
        MissionConfig(threads=threads)


@pytest.mark.parametrize("threads", [1, 2])
def test_a_mission_replan_solves_with_the_configured_threads(monkeypatch, threads):
    """A re-plan from a stored mid-episode state runs the real planner with MissionConfig.threads."""
    seen = []
    real = mission.plan_spatially_robust

    def spy(scenario, config):
        seen.append(config.solver_options.threads)
        return real(scenario, config)

    monkeypatch.setattr(mission, "plan_spatially_robust", spy)
    case = json.loads(CASE.read_text())
    plan = Plan.from_dict(case["plan"])
    planner = MissionPlanner(load_scenario(case["scenario"]), plan, MissionConfig(threads=threads),
                             PlannerConfig(threads=None), aim_final_position=True)
    planner.trace = list(np.array(case["trace_m"])[:-1])
    book = ImpactBook(plan.impacts, tolerance_s=2.0)
    book.done = {0}
    index = {n: i for i, n in enumerate(case["bodies"])}
    planner.step(case["time_s"], np.array(case["states"]), index, plan, book, True, None)
    assert seen and set(seen) == {threads}  # the planner's own None does not reach the solver
    assert planner.records[0].new_robustness is not None


class _RecordingEngine:
    """Stands in for an impact_env.sweep engine: keeps the jobs, answers each with a planner error."""

    def __init__(self):
        self.jobs = []

    def map(self, fn, jobs):
        self.jobs = list(jobs)
        return [{"scenario": name, "plan": None, "error": "not planned", "wall_s": 0.0} for name, _, _ in self.jobs]


@pytest.mark.parametrize("threads, expected", [(None, 1), (3, 3)])
def test_a_planned_list_pins_one_thread_per_job_unless_configured(threads, expected):
    engine = _RecordingEngine()
    outcomes = plan_scenarios(["corridor", "relay"], PlannerConfig(threads=threads), engine)
    assert [o.error for o in outcomes] == ["not planned", "not planned"]
    assert [options["solver_options"].threads for _, _, options in engine.jobs] == [expected, expected]
