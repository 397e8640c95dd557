"""A small mixed-integer linear model: variables, linear expressions, named constraint groups.

Why not a modelling library: the planner needs one model that three solvers (HiGHS, SCIP, Gurobi) can
take, constraint *groups* for infeasibility diagnosis (re-solve with groups left out), and nothing else;
PuLP's CBC misreports time-limit stops as optimal and CasADi's CBC plugin returned wrong answers on these
models (docs/background.md). The model is plain data: the backends in ``planners/offline/solvers``
turn it into their own API.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

INF = math.inf


class LinExpr:
    """sum(coef * x[idx]) + const. Supports +, -, scalar *, and <=, >=, == (giving a Constraint)."""

    __slots__ = ("terms", "const")

    def __init__(self, terms: dict[int, float] | None = None, const: float = 0.0) -> None:
        self.terms = terms if terms is not None else {}
        self.const = float(const)

    @staticmethod
    def of(value: LinExpr | float | int) -> LinExpr:
        if isinstance(value, LinExpr):
            return value
        return LinExpr({}, float(value))

    def copy(self) -> LinExpr:
        return LinExpr(dict(self.terms), self.const)

    def __add__(self, other: LinExpr | float) -> LinExpr:
        out = self.copy()
        if isinstance(other, LinExpr):
            t = out.terms
            for k, v in other.terms.items():
                t[k] = t.get(k, 0.0) + v
            out.const += other.const
        else:
            out.const += float(other)
        return out

    __radd__ = __add__

    def __neg__(self) -> LinExpr:
        return LinExpr({k: -v for k, v in self.terms.items()}, -self.const)

    def __sub__(self, other: LinExpr | float) -> LinExpr:
        return self + (-other if isinstance(other, LinExpr) else -float(other))

    def __rsub__(self, other: LinExpr | float) -> LinExpr:
        return (-self) + other

    def __mul__(self, k: float) -> LinExpr:
        if isinstance(k, LinExpr):
            raise TypeError("the product of two expressions is not linear")
        k = float(k)
        return LinExpr({i: k * v for i, v in self.terms.items()}, k * self.const)

    __rmul__ = __mul__

    def __truediv__(self, k: float) -> LinExpr:
        return self * (1.0 / float(k))

    def __le__(self, other: LinExpr | float) -> Constraint:
        return Constraint(self - other, -INF, 0.0)

    def __ge__(self, other: LinExpr | float) -> Constraint:
        return Constraint(self - other, 0.0, INF)

    def __eq__(self, other: LinExpr | float) -> Constraint:  # type: ignore[override]
        return Constraint(self - other, 0.0, 0.0)

    __hash__ = None  # type: ignore[assignment]

    def value(self, x: np.ndarray) -> float:
        """Value at the solution vector ``x``."""
        return self.const + sum(v * x[i] for i, v in self.terms.items())

    def __repr__(self) -> str:
        parts = [f"{v:+g}*x{i}" for i, v in sorted(self.terms.items())]
        return " ".join(parts + [f"{self.const:+g}"])


@dataclass
class Constraint:
    """lo <= expr <= hi (the expression's constant is moved to the bounds when stored)."""

    expr: LinExpr
    lo: float
    hi: float


@dataclass
class Model:
    """Variables with bounds and integrality, constraint rows in named groups, a linear objective."""

    name: str = "model"
    col_lo: list[float] = field(default_factory=list)
    col_hi: list[float] = field(default_factory=list)
    integer: list[bool] = field(default_factory=list)
    col_names: list[str] = field(default_factory=list)
    rows: list[tuple[dict[int, float], float, float]] = field(default_factory=list)
    row_groups: list[str] = field(default_factory=list)
    objective: LinExpr = field(default_factory=LinExpr)
    maximize: bool = True
    # optional convex quadratic objective term: sum over (i, j) of q * x_i * x_j, with i <= j
    quadratic: dict[tuple[int, int], float] = field(default_factory=dict)

    # ------------------------------------------------------------------------------------- variables
    def add_var(self, lo: float = -INF, hi: float = INF, integer: bool = False, name: str = "") -> LinExpr:
        if lo > hi:
            raise ValueError(f"variable {name!r} has lower bound {lo} > upper bound {hi}")
        self.col_lo.append(float(lo))
        self.col_hi.append(float(hi))
        self.integer.append(bool(integer))
        self.col_names.append(name)
        return LinExpr({len(self.col_lo) - 1: 1.0})

    def add_binary(self, name: str = "") -> LinExpr:
        return self.add_var(0.0, 1.0, integer=True, name=name)

    @property
    def n_vars(self) -> int:
        return len(self.col_lo)

    @property
    def n_binaries(self) -> int:
        return sum(self.integer)

    @property
    def n_rows(self) -> int:
        return len(self.rows)

    # ----------------------------------------------------------------------------------- constraints
    def add(self, constraint: Constraint | Iterable[Constraint], group: str) -> None:
        """Add one constraint or several, all in ``group`` (used to explain infeasibility)."""
        if isinstance(constraint, Constraint):
            constraint = (constraint,)
        for c in constraint:
            terms = {k: v for k, v in c.expr.terms.items() if v != 0.0}
            lo, hi = c.lo - c.expr.const, c.hi - c.expr.const
            if not terms:
                if lo > 1e-9 or hi < -1e-9:
                    raise ValueError(f"constant constraint in group {group!r} can never hold ({lo} <= 0 <= {hi})")
                continue
            self.rows.append((terms, lo, hi))
            self.row_groups.append(group)

    def set_objective(self, expr: LinExpr, maximize: bool = True) -> None:
        self.objective = LinExpr.of(expr)
        self.maximize = maximize

    def groups(self) -> list[str]:
        """Constraint group names in order of first appearance."""
        return list(dict.fromkeys(self.row_groups))

    def without_groups(self, dropped: set[str]) -> Model:
        """A copy with the rows of the ``dropped`` groups removed (variables and objective kept)."""
        keep = [i for i, g in enumerate(self.row_groups) if g not in dropped]
        return Model(self.name, self.col_lo, self.col_hi, self.integer, self.col_names,
                     [self.rows[i] for i in keep], [self.row_groups[i] for i in keep], self.objective,
                     self.maximize, self.quadratic)

    def add_quadratic(self, expr: LinExpr, weight: float = 1.0) -> None:
        """Add ``weight * expr**2`` (the expression's constant included) to a minimised objective."""
        if self.maximize:
            raise ValueError("quadratic terms need a minimised objective: call set_objective(..., maximize=False)")
        items = list(expr.terms.items())
        for a, (i, ci) in enumerate(items):
            for j, cj in items[a:]:
                key = (i, j) if i <= j else (j, i)
                self.quadratic[key] = self.quadratic.get(key, 0.0) + weight * ci * cj * (1.0 if i == j else 2.0)
        if expr.const:  # (e + c)^2 = e^2 + 2 c e + c^2; the constant c^2 does not move the optimum
            self.objective = self.objective + LinExpr(dict(expr.terms)) * (2.0 * weight * expr.const)

    def csr(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Row-wise sparse matrix (start, index, value) and row bounds (lo, hi) as numpy arrays."""
        start = np.zeros(self.n_rows + 1, dtype=np.int32)
        index: list[int] = []
        value: list[float] = []
        lo = np.empty(self.n_rows)
        hi = np.empty(self.n_rows)
        for r, (terms, rlo, rhi) in enumerate(self.rows):
            index.extend(terms.keys())
            value.extend(terms.values())
            start[r + 1] = len(index)
            lo[r], hi[r] = rlo, rhi
        return start, np.array(index, dtype=np.int32), np.array(value, dtype=float), lo, hi

    def objective_vector(self) -> np.ndarray:
        c = np.zeros(self.n_vars)
        for i, v in self.objective.terms.items():
            c[i] = v
        return c

    def check(self, x: np.ndarray, tol: float = 1e-6) -> list[str]:
        """Rows and bounds violated by ``x`` by more than ``tol`` (for tests and debugging)."""
        bad = []
        for i, (lo, hi) in enumerate(zip(self.col_lo, self.col_hi)):
            if x[i] < lo - tol or x[i] > hi + tol:
                bad.append(f"variable {self.col_names[i] or i} = {x[i]} outside [{lo}, {hi}]")
            if self.integer[i] and abs(x[i] - round(x[i])) > tol:
                bad.append(f"variable {self.col_names[i] or i} = {x[i]} is not integral")
        for (terms, lo, hi), g in zip(self.rows, self.row_groups):
            v = sum(c * x[k] for k, c in terms.items())
            if v < lo - tol or v > hi + tol:
                bad.append(f"row in {g!r}: {v} outside [{lo}, {hi}]")
        return bad
