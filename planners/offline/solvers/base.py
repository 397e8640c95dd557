"""The interface every solver backend implements, and the result it returns."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum

import numpy as np


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


@dataclass
class SolverOptions:
    """Options every backend honours.

    time_limit_s: wall-clock limit (None: none). mip_gap: relative gap at which to stop. threads: None lets
    the solver choose. verbose: the solver's own log on stdout. warm_start: a full solution vector (NaN for
    unknown entries) given to the solver as a starting incumbent. progress: called about once a second
    with a :class:`Progress` during MIP solves. seed: the solver's random seed (solve times vary ~2x with it).
    node_limit: stop a MIP after this many branch-and-bound nodes (1: the root node only). Unlike a time
    limit it is a deterministic amount of work: the same model, options and seed stop at the same incumbent
    however loaded the machine is. heuristics: False switches the MIP's primal heuristics off (HiGHS
    ``mip_heuristic_effort = 0``, SCIP's heuristics emphasis off, Gurobi ``Heuristics = 0``): with a good warm
    start they can cost more than a node limit bounds (the impact-robust planner's stage 2).
    """

    time_limit_s: float | None = None
    mip_gap: float = 1e-4
    threads: int | None = None
    verbose: bool = False
    warm_start: np.ndarray | None = None
    progress: Callable[[Progress], None] | None = None
    seed: int = 0
    node_limit: int | None = None
    heuristics: bool = True


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

    @property
    def has_solution(self) -> bool:
        return self.x is not None
