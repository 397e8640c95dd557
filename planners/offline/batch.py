"""Plan a list of scenarios side by side on the sweep engine: ``impact-env plan corridor,relay,two_objects``.

Each scenario is one job of :mod:`impact_env.sweep` (local processes, or Ray tasks with ``--engine ray``): the
spatially robust planner with the same :class:`~planners.offline.config.PlannerConfig`, or the impact-robust
one when the config is an :class:`~planners.offline.config.IRPlannerConfig`. The budgets are node counts and
the solver's threads are pinned: the config's (``PlannerConfig``'s default is 2, so each plan is the one
``plan_spatially_robust`` gives on its own), else 1 per job (HiGHS left to choose takes a count from the
worker's cores, and its search depends on the count), so a scenario's plan is the same on any worker, bit for
bit (``Plan.fingerprint()``). A scenario
whose task is infeasible, or that hits the time limit without a plan, does not stop the others: its outcome
carries the error's message.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from typing import Any

from planners.errors import PlannerError, PlanTimeoutError
from planners.offline.config import PlannerConfig
from planners.plan import Plan


@dataclass
class PlanOutcome:
    """One scenario's result: the plan (None if it failed), whether the time limit cut it, the error's text."""

    scenario: str
    plan: Plan | None
    timed_out: bool = False
    error: str | None = None
    wall_s: float = 0.0


def plan_job(job: tuple[str, str, dict[str, Any]]) -> dict[str, Any]:
    """A sweep job: plan one scenario (name, "sr" or "ir", config fields); JSON data back (a plan travels as
    its dict)."""
    from impact_env.transport.scenario import load_scenario
    from planners.offline.impact_robust import IRPlannerConfig, plan_impact_robust
    from planners.offline.spatially_robust import plan_spatially_robust

    name, kind, options = job
    start = time.perf_counter()
    try:
        if kind == "ir":
            plan = plan_impact_robust(load_scenario(name), IRPlannerConfig(**options))
        else:
            plan = plan_spatially_robust(load_scenario(name), PlannerConfig(**options))
        return {"scenario": name, "plan": plan.to_dict(), "wall_s": time.perf_counter() - start}
    except PlanTimeoutError as exc:
        best = None if exc.plan is None else exc.plan.to_dict()
        return {"scenario": name, "plan": best, "timed_out": True, "error": None if best else str(exc),
                "wall_s": time.perf_counter() - start}
    except PlannerError as exc:
        return {"scenario": name, "plan": None, "error": str(exc), "wall_s": time.perf_counter() - start}


def plan_scenarios(names: list[str], config: PlannerConfig, engine: Any) -> list[PlanOutcome]:
    """Plan every scenario in ``names`` with ``config`` on an open :class:`impact_env.sweep.Engine`."""
    if config.solver_options.progress is not None or config.warm_start is not None:
        raise PlannerError("planning a list of scenarios takes no progress callback and no warm start")
    from planners.offline.impact_robust import IRPlannerConfig

    kind = "ir" if isinstance(config, IRPlannerConfig) else "sr"
    options = {f.name: getattr(config, f.name) for f in dataclasses.fields(config)}
    if options["solver_options"].threads is None:
        options["solver_options"] = dataclasses.replace(options["solver_options"], threads=1)
    outcomes = []
    for r in engine.map(plan_job, [(name, kind, options) for name in names]):
        plan = None if r["plan"] is None else Plan.from_dict(r["plan"])
        outcomes.append(PlanOutcome(r["scenario"], plan, r.get("timed_out", False), r.get("error"), r["wall_s"]))
    return outcomes
