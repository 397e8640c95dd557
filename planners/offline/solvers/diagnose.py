"""Why is a model infeasible? Group-level conflict search, and the 'infeasible or unbounded' tie-break.

Both work by re-solving a copy of the model with a zero objective: infeasibility does not depend on the
objective, a zero objective can never be unbounded, and a pure feasibility problem usually solves fast.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable

from planners.errors import InfeasiblePlanError
from planners.offline.milp.model import LinExpr, Model
from planners.offline.solvers.base import SolveResult, SolverOptions, Status

DEFAULT_CHECK_TIME_LIMIT_S = 10.0


def feasibility_model(model: Model) -> Model:
    """The same variables and rows with a zero objective (the model's lists are shared, not copied)."""
    return dataclasses.replace(model, objective=LinExpr(), quadratic={})


def resolve_infeasible_or_unbounded(solve_fn: Callable[[Model, SolverOptions], SolveResult], model: Model,
                                    options: SolverOptions, t0: float, solver: str) -> SolveResult:
    """Turn a solver's 'infeasible or unbounded' into INFEASIBLE or UNBOUNDED.

    Solves the zero-objective model with ``solve_fn`` in the time that remains: infeasible there ->
    INFEASIBLE; feasible -> UNBOUNDED (x and objective None, as for every UNBOUNDED result). ``t0`` is the
    ``time.perf_counter()`` at which the original solve started.
    """
    remaining = None
    if options.time_limit_s is not None:
        remaining = max(options.time_limit_s - (time.perf_counter() - t0), 0.0)
    check = solve_fn(feasibility_model(model),
                     dataclasses.replace(options, time_limit_s=remaining, progress=None, warm_start=None))
    elapsed = time.perf_counter() - t0
    if check.status is Status.INFEASIBLE:
        return SolveResult(Status.INFEASIBLE, None, None, None, None, elapsed, solver)
    if check.status is Status.OPTIMAL:
        return SolveResult(Status.UNBOUNDED, None, None, None, None, elapsed, solver,
                           "feasible, and the objective is unbounded")
    status = Status.TIME_LIMIT if check.status is Status.TIME_LIMIT else Status.ERROR
    return SolveResult(status, None, None, None, None, elapsed, solver,
                       "infeasible or unbounded (not told apart within the limits)")


def _check_options(options: SolverOptions | None) -> SolverOptions:
    base = options or SolverOptions()
    return dataclasses.replace(base, time_limit_s=base.time_limit_s or DEFAULT_CHECK_TIME_LIMIT_S,
                               warm_start=None, progress=None)


def _proven_infeasible(model: Model, solver: str, options: SolverOptions) -> bool:
    from planners.offline.solvers import solve  # the package imports nothing from here at import time

    return solve(model, solver, options).status is Status.INFEASIBLE


def conflicting_groups(model: Model, solver: str = "highs", options: SolverOptions | None = None) -> list[str]:
    """A minimal set of constraint groups that cannot hold together (a group-level IIS), by deletion filter.

    Starting from all groups in ``model.groups()`` order, each group is dropped tentatively; if the model
    is still infeasible without it, it stays dropped, otherwise it is kept. The kept groups are infeasible
    together and each one is needed for that. Every check solves the zero-objective model with
    ``options.time_limit_s`` (10 s if None); a check that ends without a proof of infeasibility (time limit,
    error) counts as "maybe feasible", so the group is kept: the result is then still infeasible together but
    possibly not minimal. Returns [] if the full model is not proven infeasible, and also if it is infeasible
    through variable bounds and integrality alone (no group needed).
    """
    opts = _check_options(options)
    feasibility = feasibility_model(model)
    if not _proven_infeasible(feasibility, solver, opts):
        return []
    groups = model.groups()
    dropped: set[str] = set()
    for group in groups:
        if _proven_infeasible(feasibility.without_groups(dropped | {group}), solver, opts):
            dropped.add(group)
    return [g for g in groups if g not in dropped]


def explain_infeasible(model: Model, solver: str = "highs", options: SolverOptions | None = None
                       ) -> InfeasiblePlanError:
    """An :class:`InfeasiblePlanError` naming the conflicting groups (``.groups``), for the caller to raise.

    Call it after a solve reported INFEASIBLE; it re-solves the model once per group (see
    :func:`conflicting_groups`).
    """
    groups = conflicting_groups(model, solver, options)
    if groups:
        names = ", ".join(repr(g) for g in groups)
        message = f"infeasible: no plan satisfies the task; these constraint groups conflict: {names}"
    elif _proven_infeasible(feasibility_model(model).without_groups(set(model.groups())), solver,
                            _check_options(options)):
        message = "infeasible: no plan satisfies the task; the variable bounds and integrality alone admit no solution"
    else:
        message = ("infeasible: no plan satisfies the task, but the solver could not prove which constraint groups "
                   "conflict within the time limit per check")
    return InfeasiblePlanError(message, groups)
