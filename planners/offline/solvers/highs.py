"""HiGHS backend (highspy): the whole model passed at once as one HighsLp.

HiGHS solves LPs, MILPs and convex QPs, but not MIQPs. Never import casadi in a process that uses this
module: highspy and CasADi's bundled HiGHS plugin each ship a ``libhighs.so.1`` and cannot both be loaded
(docs/background.md).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import highspy
import numpy as np

from planners.offline.milp.model import Model
from planners.offline.solvers.base import Progress, SolveResult, SolverOptions, Status, limit_message
from planners.offline.solvers.diagnose import resolve_infeasible_or_unbounded

NAME = "highs"
_REPORT_INTERVAL_S = 1.0
_scheduler_threads: int | None = None  # thread count this module last sized HiGHS's global scheduler to


class _Highs(highspy.Highs):
    """``highspy.Highs`` that is silent from its first call when ``verbose`` is false.

    HiGHS logs its banner ("Running HiGHS ...") on the first call to an instance while ``output_flag`` is
    still true, and says to set ``output_flag`` before any other call to suppress it. highspy's constructor
    makes such a call itself (``enableCallbacks``), so the flag is set at the start of that call, before
    the call reaches HiGHS.
    """

    def __init__(self, verbose: bool) -> None:
        self._verbose = bool(verbose)
        super().__init__()

    def enableCallbacks(self) -> None:  # noqa: N802 - highspy's name
        self.setOptionValue("output_flag", self._verbose)
        super().enableCallbacks()


def _lp(model: Model) -> highspy.HighsLp:
    """The model's linear part as a HighsLp (row-wise matrix, objective sense and offset included)."""
    start, index, value, row_lo, row_hi = model.csr()
    lp = highspy.HighsLp()
    lp.num_col_ = model.n_vars
    lp.num_row_ = model.n_rows
    lp.col_cost_ = model.objective_vector()
    lp.offset_ = model.objective.const
    lp.sense_ = highspy.ObjSense.kMaximize if model.maximize else highspy.ObjSense.kMinimize
    lp.col_lower_ = np.asarray(model.col_lo, dtype=float)
    lp.col_upper_ = np.asarray(model.col_hi, dtype=float)
    lp.row_lower_ = row_lo
    lp.row_upper_ = row_hi
    lp.a_matrix_.format_ = highspy.MatrixFormat.kRowwise
    lp.a_matrix_.num_col_ = model.n_vars
    lp.a_matrix_.num_row_ = model.n_rows
    lp.a_matrix_.start_ = start
    lp.a_matrix_.index_ = index
    lp.a_matrix_.value_ = value
    if any(model.integer):
        lp.integrality_ = [highspy.HighsVarType.kInteger if k else highspy.HighsVarType.kContinuous
                           for k in model.integer]
    return lp


def hessian_csc(model: Model) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """HiGHS's Hessian (start, index, value) for the model's ``sum q_ij x_i x_j``.

    HiGHS adds 0.5 x'Qx with Q given by its lower triangle, column-wise. Matching coefficients: a diagonal
    term q_ii x_i^2 needs Q_ii = 2 q_ii; an off-diagonal q_ij x_i x_j (i < j) appears twice in 0.5 x'Qx, so
    Q_ji = q_ij (row j >= column i).
    """
    n = model.n_vars
    entries = sorted((i, j, 2.0 * q if i == j else q) for (i, j), q in model.quadratic.items() if q != 0.0)
    start = np.zeros(n + 1, dtype=np.int32)
    for col, _, _ in entries:
        start[col + 1] += 1
    start = np.cumsum(start, dtype=np.int32)
    index = np.array([row for _, row, _ in entries], dtype=np.int32)
    value = np.array([v for _, _, v in entries], dtype=float)
    return start, index, value


def _set_options(h: highspy.Highs, options: SolverOptions) -> None:
    h.setOptionValue("output_flag", bool(options.verbose))
    h.setOptionValue("log_to_console", bool(options.verbose))
    if options.time_limit_s is not None:
        h.setOptionValue("time_limit", float(max(options.time_limit_s, 0.0)))
    h.setOptionValue("mip_rel_gap", float(options.mip_gap))
    h.setOptionValue("random_seed", int(options.seed))
    if options.node_limit is not None:
        h.setOptionValue("mip_max_nodes", int(options.node_limit))
    if not options.heuristics:
        h.setOptionValue("mip_heuristic_effort", 0.0)
    if options.threads is not None:
        # HiGHS sizes one process-wide scheduler on first use and refuses a later, different `threads`
        # (model status kNotset) unless the scheduler is reset; do not change `threads` while another
        # HiGHS solve runs in a second Python thread.
        global _scheduler_threads
        if options.threads != _scheduler_threads:
            h.resetGlobalScheduler(True)
            _scheduler_threads = int(options.threads)
        h.setOptionValue("threads", int(options.threads))


def _set_warm_start(h: highspy.Highs, model: Model, x0: np.ndarray) -> None:
    """Give a (possibly partial: NaN = unknown) solution; HiGHS completes a partial one itself."""
    x0 = np.asarray(x0, dtype=float)
    if x0.shape != (model.n_vars,):
        raise ValueError(f"warm_start must have shape ({model.n_vars},), got {x0.shape}")
    known = np.flatnonzero(np.isfinite(x0))
    if known.size == 0:
        return
    values = np.clip(x0[known], np.asarray(model.col_lo)[known], np.asarray(model.col_hi)[known])
    integer = np.asarray(model.integer, dtype=bool)[known]
    values[integer] = np.round(values[integer])
    h.setSolution(int(known.size), known.astype(np.int32), values)


def _attach_progress(h: highspy.Highs, report: Callable[[Progress], None], errors: list[BaseException]) -> None:
    """Report progress from kCallbackMipInterrupt, at most once per interval of HiGHS's running time.

    The interrupt callback fires very often (every node and more), so the common path is one attribute
    read and one comparison. An exception in the user's callback stops the solve and is re-raised after it.
    """
    next_at = [_REPORT_INTERVAL_S]

    def on_interrupt(event: highspy.HighsCallbackEvent) -> None:
        # Everything inside the try: an exception escaping into HiGHS's C++ (a KeyboardInterrupt can land
        # on any bytecode here) would unwind through the solver instead of stopping it cleanly.
        try:
            out = event.data_out
            t = out.running_time
            if t < next_at[0]:
                return
            next_at[0] = t + _REPORT_INTERVAL_S
            primal, dual, gap = out.mip_primal_bound, out.mip_dual_bound, out.mip_gap
            has_incumbent = math.isfinite(primal)
            report(Progress(elapsed_s=t, incumbent=primal if has_incumbent else None,
                            bound=dual if math.isfinite(dual) else None,
                            gap=gap if has_incumbent and math.isfinite(gap) else None))
        except BaseException as err:  # noqa: BLE001 - handed back to the caller after the solve
            errors.append(err)
            event.interrupt()

    h.cbMipInterrupt.subscribe(on_interrupt)


def solve(model: Model, options: SolverOptions | None = None) -> SolveResult:
    """Solve ``model`` with HiGHS. Raises ValueError for a quadratic objective with integer variables."""
    options = options or SolverOptions()
    is_mip = any(model.integer)
    if model.quadratic and is_mip:
        raise ValueError("HiGHS does not solve mixed-integer QPs (quadratic objective with integer variables): "
                         "use solver='scip' or 'gurobi', or make the objective linear")
    t0 = time.perf_counter()
    h = _Highs(verbose=options.verbose)
    _set_options(h, options)
    status = h.passModel(_lp(model))
    if status == highspy.HighsStatus.kError:
        return SolveResult(Status.ERROR, None, None, None, None, time.perf_counter() - t0, NAME,
                           "HiGHS rejected the model (passModel)")
    if model.quadratic:
        start, index, value = hessian_csc(model)
        status = h.passHessian(model.n_vars, int(value.size), int(highspy.HessianFormat.kTriangular),
                               start, index, value)
        if status == highspy.HighsStatus.kError:
            return SolveResult(Status.ERROR, None, None, None, None, time.perf_counter() - t0, NAME,
                               "HiGHS rejected the quadratic objective (passHessian)")
    if options.warm_start is not None:
        _set_warm_start(h, model, options.warm_start)
    errors: list[BaseException] = []
    if options.progress is not None and is_mip:
        _attach_progress(h, options.progress, errors)
    h.run()
    if errors:
        raise errors[0]
    if h.getModelStatus() == highspy.HighsModelStatus.kUnboundedOrInfeasible:
        # presolve's verdict (common for MIPs): tell the two apart with a zero objective
        return resolve_infeasible_or_unbounded(solve, model, options, t0, NAME)
    result = _result(h, model, is_mip, time.perf_counter() - t0)
    if is_mip:
        result.nodes = int(h.getInfo().mip_node_count)
    return result


def _result(h: highspy.Highs, model: Model, is_mip: bool, elapsed_s: float) -> SolveResult:
    ms = h.getModelStatus()
    info = h.getInfo()
    has_x = info.primal_solution_status == highspy.SolutionStatus.kSolutionStatusFeasible
    x = np.array(h.getSolution().col_value, dtype=float) if has_x else None
    objective = info.objective_function_value if has_x else None
    if is_mip:
        bound = info.mip_dual_bound if math.isfinite(info.mip_dual_bound) else None
        gap = info.mip_gap if has_x and math.isfinite(info.mip_gap) else None
    else:
        bound, gap = objective, 0.0 if has_x else None  # HiGHS reports mip_gap = inf for LPs
    S = highspy.HighsModelStatus
    if ms == S.kOptimal:
        return SolveResult(Status.OPTIMAL, x, objective, bound, gap if gap is not None else 0.0, elapsed_s, NAME)
    if ms == S.kModelEmpty:  # no rows and no columns
        return SolveResult(Status.OPTIMAL, np.zeros(0), model.objective.const, model.objective.const, 0.0,
                           elapsed_s, NAME)
    if ms == S.kInfeasible:
        return SolveResult(Status.INFEASIBLE, None, None, None, None, elapsed_s, NAME)
    if ms == S.kUnbounded:
        return SolveResult(Status.UNBOUNDED, None, None, None, None, elapsed_s, NAME)
    if ms == S.kTimeLimit:
        if not is_mip:
            bound = gap = None
        return SolveResult(Status.TIME_LIMIT, x, objective, bound, gap, elapsed_s, NAME,
                           limit_message("time", has_x))
    if ms == S.kSolutionLimit and is_mip and h.getOptions().mip_max_nodes <= info.mip_node_count:
        # HiGHS reports its node limit (and the leaf and improving-solution limits, which we never set) as
        # kSolutionLimit
        return SolveResult(Status.NODE_LIMIT, x, objective, bound, gap, elapsed_s, NAME,
                           limit_message("node", has_x))
    return SolveResult(Status.ERROR, x, objective, None, None, elapsed_s, NAME,
                       f"HiGHS stopped with model status {h.modelStatusToString(ms)!r}")

