"""Gurobi backend (gurobipy >= 11; needs a licence, the pip wheel's own one is limited to 2000 vars/rows).

Rows are added one by one with ``addLConstr(LinExpr(coeffs, vars), ...)``: gurobipy's matrix API needs
scipy, which this project does not depend on. Gurobi solves MIQPs natively; warm starts may be partial
(unknown entries are left at ``GRB.UNDEFINED`` and Gurobi completes them).

INF_OR_UNBD is resolved like in the other backends, by re-solving with a zero objective, rather than with
DualReductions=0: Gurobi's UNBOUNDED only promises an improving ray, not a feasible point, so an
UNBOUNDED without a solution goes through the same check.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import gurobipy as gp
import numpy as np
from gurobipy import GRB

from planners.errors import SolverNotAvailableError
from planners.offline.milp.model import Model
from planners.offline.solvers.base import Progress, SolveResult, SolverOptions, Status, limit_message
from planners.offline.solvers.diagnose import resolve_infeasible_or_unbounded

NAME = "gurobi"
_REPORT_INTERVAL_S = 1.0
_LICENCE_ERRORS = (GRB.Error.NO_LICENSE, GRB.Error.SIZE_LIMIT_EXCEEDED)


def _bound(v: float) -> float:
    return v if math.isfinite(v) else math.copysign(GRB.INFINITY, v)


def _build(model: Model, env: gp.Env) -> tuple[gp.Model, list]:
    m = gp.Model(model.name, env=env)
    c = model.objective_vector()
    xs = [m.addVar(lb=_bound(lo), ub=_bound(hi), name=model.col_names[j] or f"x{j}",
                   vtype=(GRB.BINARY if (lo, hi) == (0.0, 1.0) else GRB.INTEGER) if model.integer[j]
                   else GRB.CONTINUOUS)
          for j, (lo, hi) in enumerate(zip(model.col_lo, model.col_hi))]
    for r, (row, lo, hi) in enumerate(model.rows):
        expr = gp.LinExpr(list(row.values()), [xs[j] for j in row])
        if lo == hi:
            m.addLConstr(expr, GRB.EQUAL, lo, name=f"r{r}")
            continue
        if math.isfinite(lo):
            m.addLConstr(expr, GRB.GREATER_EQUAL, lo, name=f"r{r}_lo")
        if math.isfinite(hi):
            m.addLConstr(expr, GRB.LESS_EQUAL, hi, name=f"r{r}_hi")
    objective: gp.LinExpr | gp.QuadExpr = gp.LinExpr(c.tolist(), xs) + model.objective.const
    if model.quadratic:
        quad = gp.QuadExpr()
        for (i, j), q in model.quadratic.items():
            quad.add(xs[i] * xs[j], q)
        objective = objective + quad
    m.setObjective(objective, GRB.MAXIMIZE if model.maximize else GRB.MINIMIZE)
    return m, xs


def _attr(m: gp.Model, name: str) -> float | None:
    """A numeric model attribute, or None where Gurobi has no finite value for it."""
    try:
        value = float(m.getAttr(name))
    except gp.GurobiError:
        return None
    return value if math.isfinite(value) and abs(value) < GRB.INFINITY else None


def _set_options(m: gp.Model, options: SolverOptions) -> None:
    if options.time_limit_s is not None:
        m.Params.TimeLimit = max(options.time_limit_s, 0.0)
    if options.node_limit is not None:
        m.Params.NodeLimit = int(options.node_limit)
    if not options.heuristics:
        m.Params.Heuristics = 0.0
    m.Params.MIPGap = options.mip_gap
    m.Params.Seed = options.seed
    if options.threads is not None:
        m.Params.Threads = options.threads


def _set_warm_start(model: Model, xs: list, x0: np.ndarray) -> None:
    x0 = np.asarray(x0, dtype=float)
    if x0.shape != (model.n_vars,):
        raise ValueError(f"warm_start must have shape ({model.n_vars},), got {x0.shape}")
    for j in np.flatnonzero(np.isfinite(x0)):
        v = min(max(float(x0[j]), model.col_lo[j]), model.col_hi[j])
        xs[j].Start = float(round(v)) if model.integer[j] else v


def _progress_callback(report: Callable[[Progress], None], errors: list[BaseException]):
    """A Gurobi callback reporting from the MIP callback, at most once per interval of run time."""
    next_at = [_REPORT_INTERVAL_S]

    def callback(m: gp.Model, where: int) -> None:
        if where != GRB.Callback.MIP:
            return
        try:
            t = m.cbGet(GRB.Callback.RUNTIME)
            if t < next_at[0]:
                return
            next_at[0] = t + _REPORT_INTERVAL_S
            best, bound = m.cbGet(GRB.Callback.MIP_OBJBST), m.cbGet(GRB.Callback.MIP_OBJBND)
            has_incumbent = abs(best) < GRB.INFINITY
            gap = abs(best - bound) / abs(best) if has_incumbent and best != 0.0 else None
            report(Progress(elapsed_s=t, incumbent=best if has_incumbent else None,
                            bound=bound if abs(bound) < GRB.INFINITY else None, gap=gap))
        except BaseException as err:  # noqa: BLE001 - handed back to the caller after the solve
            errors.append(err)
            m.terminate()

    return callback


def solve(model: Model, options: SolverOptions | None = None) -> SolveResult:
    """Solve ``model`` with Gurobi. Raises SolverNotAvailableError when the licence refuses the model."""
    options = options or SolverOptions()
    t0 = time.perf_counter()
    try:
        with gp.Env(empty=True) as env:
            env.setParam("OutputFlag", 1 if options.verbose else 0)
            env.start()
            m, xs = _build(model, env)
            with m:
                return _solve(m, xs, model, options, t0)
    except gp.GurobiError as err:
        if err.errno in _LICENCE_ERRORS:
            raise SolverNotAvailableError(f"Gurobi is installed but its licence refuses this model: {err}") from err
        return SolveResult(Status.ERROR, None, None, None, None, time.perf_counter() - t0, NAME, f"Gurobi: {err}")


def _solve(m: gp.Model, xs: list, model: Model, options: SolverOptions, t0: float) -> SolveResult:
    _set_options(m, options)
    if options.warm_start is not None:
        _set_warm_start(model, xs, options.warm_start)
    errors: list[BaseException] = []
    if options.progress is not None:
        m.optimize(_progress_callback(options.progress, errors))
    else:
        m.optimize()
    if errors:
        raise errors[0]
    status = m.Status
    if status == GRB.INF_OR_UNBD or (status == GRB.UNBOUNDED and m.SolCount == 0):
        # Gurobi's UNBOUNDED means "has an improving ray", not "is feasible": check feasibility too
        return resolve_infeasible_or_unbounded(solve, model, options, t0, NAME)
    elapsed = time.perf_counter() - t0
    has_x = m.SolCount > 0
    x = np.array(m.getAttr("X", xs), dtype=float) if has_x else None
    objective = m.ObjVal if has_x else None
    bound = gap = None
    if m.IsMIP and status in (GRB.OPTIMAL, GRB.TIME_LIMIT, GRB.NODE_LIMIT):
        bound = _attr(m, "ObjBound")
        gap = _attr(m, "MIPGap") if has_x else None
    elif has_x and status == GRB.OPTIMAL:
        bound, gap = objective, 0.0
    if status == GRB.OPTIMAL:
        return SolveResult(Status.OPTIMAL, x, objective, bound, gap if gap is not None else 0.0, elapsed, NAME)
    if status == GRB.INFEASIBLE:
        return SolveResult(Status.INFEASIBLE, None, None, None, None, elapsed, NAME)
    if status == GRB.UNBOUNDED:
        return SolveResult(Status.UNBOUNDED, None, None, None, None, elapsed, NAME)
    if status == GRB.TIME_LIMIT:
        return SolveResult(Status.TIME_LIMIT, x, objective, bound, gap, elapsed, NAME,
                           limit_message("time", has_x))
    if status == GRB.NODE_LIMIT:
        return SolveResult(Status.NODE_LIMIT, x, objective, bound, gap, elapsed, NAME,
                           limit_message("node", has_x))
    return SolveResult(Status.ERROR, x, objective, bound, gap, elapsed, NAME, f"Gurobi stopped with status {status}")
