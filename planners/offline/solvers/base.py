"""The interface every solver backend implements, and the result it returns."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from enum import Enum

import numpy as np

from impact_env.config_checks import check_flag, check_instance, check_integer, check_number, fail
from planners.errors import PlannerError


class Status(Enum):
    OPTIMAL = "optimal"
    INFEASIBLE = "infeasible"
    TIME_LIMIT = "time_limit"  # stopped on the time limit; x is the incumbent if one exists
    NODE_LIMIT = "node_limit"  # stopped on the branch-and-bound node limit; x is the incumbent if one exists
    UNBOUNDED = "unbounded"
    ERROR = "error"


@dataclass
class Progress:
    """One progress report during a MIP solve (objective in the model's own sense)."""

    elapsed_s: float
    incumbent: float | None
    bound: float | None
    gap: float | None


@dataclass(frozen=True)
class SolverOptions:
    """Options every backend honours: the solver budget, declared once (the planners' and the mission
    replanner's configs nest one as ``solver_options``).

    ``node_limit`` is a deterministic amount of work, unlike a time limit: the same model, options and seed
    stop at the same incumbent however loaded the machine is.
    """

    time_limit_s: float | None = None
    """Wall-clock limit of one solve (s); None: none."""
    mip_gap: float = 1e-4
    """Relative MIP gap at which to stop (dimensionless; 0: prove optimality)."""
    threads: int | None = None
    """Solver threads; None lets the solver choose (from the machine's cores)."""
    verbose: bool = False
    """The solver's own log on stdout."""
    warm_start: np.ndarray | None = field(default=None, compare=False)
    """A full solution vector (NaN for unknown entries) given to the solver as a starting incumbent; the
    planners set it from their own warm start."""
    progress: Callable[[Progress], None] | None = field(default=None, compare=False)
    """Called about once a second with a :class:`Progress` during MIP solves; None: no reports."""
    seed: int = 0
    """The solver's random seed (solve times vary ~2x with it)."""
    node_limit: int | None = None
    """Stop a MIP after this many branch-and-bound nodes (1: the root node only); None: no limit."""
    heuristics: bool = True
    """False switches the MIP's primal heuristics off (HiGHS ``mip_heuristic_effort = 0``, SCIP's heuristics
    emphasis off, Gurobi ``Heuristics = 0``): with a good warm start they can cost more than a node limit
    bounds (the impact-robust planner's stage 2)."""

    def __post_init__(self) -> None:
        check_number(self, "time_limit_s", PlannerError, low=0, low_open=True, none="no limit")
        check_number(self, "mip_gap", PlannerError, low=0)
        check_integer(self, "threads", PlannerError, low=1, none="the solver chooses")
        check_flag(self, "verbose", PlannerError)
        check_instance(self, "warm_start", PlannerError, np.ndarray, what="a 1-D numpy array", none="no start")
        if self.warm_start is not None and self.warm_start.ndim != 1:
            fail("SolverOptions.warm_start", self.warm_start, "a 1-D numpy array", PlannerError)
        check_instance(self, "progress", PlannerError, callable, what="a callable", none="no reports")
        check_integer(self, "seed", PlannerError, low=0, high=2**31 - 1)
        check_integer(self, "node_limit", PlannerError, low=1, none="no limit")
        check_flag(self, "heuristics", PlannerError)


def limit_message(limit: str, has_x: bool) -> str:
    """The message of a solve stopped by its ``limit`` ("time", "node"), with or without an incumbent."""
    return f"{limit} limit reached" + ("" if has_x else " before any feasible solution was found")


@dataclass
class SolveResult:
    status: Status
    x: np.ndarray | None
    objective: float | None
    bound: float | None
    mip_gap: float | None
    solve_time_s: float
    solver: str
    message: str = ""
    nodes: int | None = None
    """Branch-and-bound nodes the MIP solve explored (a measure of its work that no load changes); None: an LP,
    or a backend that does not say."""

    @property
    def has_solution(self) -> bool:
        return self.x is not None
