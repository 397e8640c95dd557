"""Solver backends behind one call: ``solve(model, solver="highs", options=None) -> SolveResult``.

Backends are imported only when used: importing this package loads no solver library (highspy must not
share a process with CasADi's bundled HiGHS plugin, docs/background.md).
"""

from __future__ import annotations

import importlib
import importlib.util

from planners.errors import SolverNotAvailableError
from planners.offline.milp.model import Model
from planners.offline.solvers.base import Progress, SolveResult, SolverOptions, Status

SOLVERS = ("highs", "scip", "gurobi")

_PACKAGES = {"highs": "highspy", "scip": "pyscipopt", "gurobi": "gurobipy"}
_INSTALL_HINTS = {
    "highs": "HiGHS needs highspy: pip install highspy",
    "scip": "SCIP needs pyscipopt: pip install 'impact_env[scip]'",
    "gurobi": "Gurobi needs gurobipy and a Gurobi licence: pip install 'impact_env[gurobi]'",
}

__all__ = ["SOLVERS", "Progress", "SolveResult", "SolverOptions", "Status", "available_solvers", "lp_optimum",
           "solve"]


def available_solvers() -> list[str]:
    """The backends whose Python package is installed (found without importing it; a licence is not checked)."""
    return [name for name in SOLVERS if importlib.util.find_spec(_PACKAGES[name]) is not None]


def solve(model: Model, solver: str = "highs", options: SolverOptions | None = None) -> SolveResult:
    """Solve ``model`` with the named backend; ValueError for an unknown name, SolverNotAvailableError if missing.

    The result's objective, bound and progress reports are in the model's own sense (a maximised model
    reports its maximum). See :class:`SolverOptions` for what every backend honours.
    """
    if solver not in SOLVERS:
        raise ValueError(f"unknown solver {solver!r}: choose one of {', '.join(SOLVERS)}")
    try:
        importlib.import_module(_PACKAGES[solver])
    except ImportError as err:
        raise SolverNotAvailableError(f"{_INSTALL_HINTS[solver]} ({err})") from err
    backend = importlib.import_module(f"planners.offline.solvers.{solver}")
    return backend.solve(model, options)


def lp_optimum(model: Model, solver: str = "highs") -> float | None:
    """The optimal objective of a small ``model`` (an LP), None if the solver does not prove it optimal: what
    the STL encoder's bound propagation needs (:class:`planners.offline.milp.stl_encoding.STLEncoder`, which
    the planners give this function to)."""
    result = solve(model, solver)
    return float(result.objective) if result.status == Status.OPTIMAL and result.objective is not None else None
