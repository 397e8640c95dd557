"""The offline plans of the shipped scenarios that the tests fly, committed in ``tests/data/plans/shipped/``.

Planning is load-dependent under a wall-clock limit (a busy machine can stop the solver at a worse
incumbent), and under pytest-xdist a module- or session-scoped fixture is set up once per worker, so a plan
solved in a fixture was solved again and again, and could differ between runs. The tests therefore fly these
files (``tests/conftest.py``: the ``shipped_plans`` and ``ir_lab`` fixtures), and one slow test per planner
(``tests/planners/offline/test_spatially_robust.py``, ``test_impact_robust.py``) plans every scenario again
with :func:`config` and checks that it gets the committed plan, or, where the solver may stop at another
optimum among ties, a plan proven optimal with the same objective: that keeps the files honest.

Each scenario is planned with a time limit far above what it needs, so that the file is the proven optimum
(stage 2 is cut by nodes, not time). After a change of a planner, write the files again::

    .venv/bin/python -m tests.shipped_plans            # every plan (tens of minutes on 2 cores)
    .venv/bin/python -m tests.shipped_plans ir:relay   # one
"""

from __future__ import annotations

import copy
import dataclasses
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from planners.offline.config import PlannerConfig
    from planners.plan import Plan

FOLDER = Path(__file__).parent / "data" / "plans" / "shipped"
SR_SCENARIOS = ("throw_and_catch_exp", "corridor", "obstacle_avoidance", "two_objects", "ping_pong_stop", "relay",
                "long_throw_trim", "held_drift", "narrow_gap", "one_robot_two_objects", "wall_start", "timed_visits",
                "four_robots")
IR_SCENARIOS = ("throw_and_catch_exp", "corridor", "obstacle_avoidance", "two_objects", "ping_pong_stop", "relay",
                "long_throw_trim", "wall_start", "narrow_gap", "held_drift", "four_robots")
# shipped scenarios the impact-robust planner finds no delta > 0 for (its answer: docs/robustness.md)
IR_INFEASIBLE = ("one_robot_two_objects", "timed_visits")
# (planner, scenario) -> stage 1's time limit (s); the relay's robustness stage takes 26 s on a lightly loaded
# 2-core machine and more than the default 60 s when every core is busy
TIME_LIMIT_S = {"sr": 600.0, "ir": 900.0}


def path(planner: str, name: str) -> Path:
    """The committed plan file of a shipped scenario: ``tests/data/plans/shipped/<planner>/<name>.json``."""
    return FOLDER / planner / f"{name}.json"


def config(planner: str) -> PlannerConfig:
    """The options the committed plans were made with: the defaults and a generous time limit; the spatially
    robust plans also with the satisfaction margin at 0 (``PlannerConfig.min_robustness_m``), the constraint they
    were made with before the margin arrived. The margin never binds on a shipped scenario (every rho is far above
    0.1 mm), so it changes no rho, but it changes the model's rows and so HiGHS's path: with it, 5 of the 13 come
    out as other plans with the same rho (two_objects, ping_pong_stop, relay, timed_visits, four_robots), and the
    robustness cells flown with the committed ones would have to be flown again."""
    from planners.offline.config import IRPlannerConfig, PlannerConfig, SolverOptions

    options = SolverOptions(time_limit_s=TIME_LIMIT_S[planner])
    if planner == "sr":
        return PlannerConfig(solver_options=options, min_robustness_m=0.0)
    return IRPlannerConfig(solver_options=options)


def plan(planner: str, name: str) -> Plan:
    """Plan a shipped scenario now with :func:`config` (what the slow honesty tests and ``main`` do)."""
    from impact_env.transport.scenario import load_scenario
    from planners.offline.impact_robust import plan_impact_robust
    from planners.offline.spatially_robust import plan_spatially_robust

    solve = {"sr": plan_spatially_robust, "ir": plan_impact_robust}[planner]
    return solve(load_scenario(name), config(planner))


def objective(plan: Plan) -> float:
    """Stage 1's objective: rho (m) of a spatially robust plan, delta (m/s) of an impact-robust one."""
    return plan.robustness if plan.planner == "sr" else float(plan.delta_mps)


def frozen(plan: Plan) -> Plan:
    """``plan`` with every numpy array in it made read-only (in place): a test that wrote into a plan other
    tests share would raise instead of changing theirs. ``copy.deepcopy`` of it is writable again."""
    def walk(x: object) -> None:
        if isinstance(x, np.ndarray):
            x.flags.writeable = False
        elif dataclasses.is_dataclass(x) and not isinstance(x, type):
            for f in dataclasses.fields(x):
                walk(getattr(x, f.name))
        elif isinstance(x, dict):
            for v in x.values():
                walk(v)
        elif isinstance(x, (list, tuple)):
            for v in x:
                walk(v)

    walk(plan)
    return plan


class ShippedPlans:
    """The committed plans, each file read once (``sr(name)``, ``ir(name)``), shared and read-only; a test
    that wants to change one takes ``copy.deepcopy`` of it."""

    def __init__(self) -> None:
        self._plans: dict[tuple[str, str], Plan] = {}

    def get(self, planner: str, name: str) -> Plan:
        key = (planner, name)
        if key not in self._plans:
            from planners.plan import Plan

            file = path(planner, name)
            if not file.exists():
                raise FileNotFoundError(f"{file} is not committed: python -m tests.shipped_plans {planner}:{name}")
            self._plans[key] = frozen(Plan.load(file))
        return self._plans[key]

    def sr(self, name: str) -> Plan:
        return self.get("sr", name)

    def ir(self, name: str) -> Plan:
        return self.get("ir", name)

    def writable(self, planner: str, name: str) -> Plan:
        """A copy of the committed plan that the caller may change."""
        return copy.deepcopy(self.get(planner, name))


def main(argv: list[str]) -> int:
    wanted = [tuple(a.split(":", 1)) for a in argv] or (
        [("sr", n) for n in SR_SCENARIOS] + [("ir", n) for n in IR_SCENARIOS])
    for planner, name in wanted:
        start = time.perf_counter()
        result = plan(planner, name)
        result.save(path(planner, name))
        print(f"{planner}:{name}: objective {objective(result):.6g}, gap {result.mip_gap:.2g}, "
              f"fingerprint {result.fingerprint()}, {time.perf_counter() - start:.0f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
