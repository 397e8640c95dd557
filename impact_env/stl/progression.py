"""STL progression: rewrite a formula for the rest of a trace once a prefix of the trace is known.

Given a formula phi, a trace prefix of samples 0..k (sample j at time j * dt) and the cut sample k,
:func:`progress` returns psi such that, for EVERY continuation of the prefix,

    rho(phi, trace, 0) = rho(psi, trace[k:], 0)              (robustness, Eq. 2a-2d, exactly)

where ``trace[k:]`` restarts the clock at sample k (which both parts share). It is the quantitative form of
formula progression: a part of phi whose samples all lie in the prefix becomes a :class:`Constant` leaf
holding its robustness, and a window that straddles the cut splits into its past samples and one shifted
operator (the rules: :func:`progress`).

:func:`without_constants` turns a progressed task into one the offline planner can take for the rest of the
mission: what the past decided cannot be changed, so a decided conjunct is dropped (satisfied or not), a
disjunct the past already satisfied makes its disjunction true, and a violated disjunct is dropped.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from impact_env.errors import STLError
from impact_env.geometry import ConvexPolygon
from impact_env.stl.formula import (
    Always,
    And,
    Constant,
    Eventually,
    FalseFormula,
    Formula,
    InRegion,
    Not,
    Or,
    TrueFormula,
    Until,
    check_dt,
    horizon_steps,
    interval_steps,
)
from impact_env.stl.robustness import robustness_signal


def _const_value(f: Formula) -> float | None:
    if isinstance(f, Constant):
        return f.value
    if isinstance(f, TrueFormula):
        return math.inf
    if isinstance(f, FalseFormula):
        return -math.inf
    return None


def _negate(f: Formula) -> Formula:
    c = _const_value(f)
    if c is not None:
        return Constant(-c)
    if isinstance(f, Not):
        return f.child
    return Not(f)


def _combine(parts: list[Formula], conjunction: bool) -> Formula:
    """And (min) or Or (max) of ``parts`` with their constants folded into one (none if it cannot matter)."""
    consts = [c for c in (_const_value(p) for p in parts) if c is not None]
    rest: list[Formula] = []
    for p in parts:
        if _const_value(p) is None:
            rest.extend(p.children if type(p) is (And if conjunction else Or) else (p,))
    if consts:
        c = min(consts) if conjunction else max(consts)
        # a constant at the identity (+inf for min, -inf for max) cannot change the value of the rest
        if not rest or c != (math.inf if conjunction else -math.inf):
            rest.append(Constant(c))
    if not rest:
        return Constant(math.inf if conjunction else -math.inf)
    if len(rest) == 1:
        return rest[0]
    return And(tuple(rest)) if conjunction else Or(tuple(rest))


class _Progressor:
    def __init__(self, formula: Formula, trace: Mapping[str, np.ndarray], regions: Mapping[str, ConvexPolygon],
                 dt: float, k: int) -> None:
        self.trace, self.regions, self.dt, self.k = trace, regions, dt, k
        self._signals: dict[int, np.ndarray] = {}
        self._memo: dict[tuple[int, int], Formula] = {}
        self._keep = [formula]  # ids in the memo stay valid while the tree lives

    def signal(self, f: Formula) -> np.ndarray:
        if id(f) not in self._signals:
            self._signals[id(f)] = robustness_signal(f, self.trace, self.regions, self.dt)
        return self._signals[id(f)]

    def shifted(self, lo: int, hi: int) -> tuple[float, float]:
        return lo * self.dt, hi * self.dt

    def at(self, f: Formula, j: int) -> Formula:
        """psi with rho(f, trace, j) = rho(psi, trace[k:], 0), for j <= k."""
        k = self.k
        if j == k:
            return f
        key = (id(f), j)
        if key in self._memo:
            return self._memo[key]
        if j + horizon_steps(f, self.dt) <= k:  # decided by the prefix
            out: Formula = Constant(float(self.signal(f)[j]))
        elif isinstance(f, Not):
            out = _negate(self.at(f.child, j))
        elif isinstance(f, (And, Or)):
            out = _combine([self.at(c, j) for c in f.children], isinstance(f, And))
        elif isinstance(f, (Eventually, Always)):
            a_k, b_k = interval_steps(f.a_s, f.b_s, self.dt)
            parts = [self.at(f.child, t) for t in range(j + a_k, min(j + b_k + 1, k))]
            if j + b_k >= k:
                lo, hi = max(j + a_k, k) - k, j + b_k - k
                parts.append(type(f)(*self.shifted(lo, hi), f.child))
            out = _combine(parts, isinstance(f, Always))
        elif isinstance(f, Until):
            a_k, b_k = interval_steps(f.a_s, f.b_s, self.dt)
            left = [self.at(f.left, s) for s in range(j, k)]
            options = [_combine([self.at(f.right, t)] + left[:t - j + 1], True)
                       for t in range(j + a_k, min(j + b_k + 1, k))]
            if j + b_k >= k:
                lo, hi = max(j + a_k, k) - k, j + b_k - k
                options.append(_combine(left + [Until(*self.shifted(lo, hi), f.left, f.right)], True))
            out = _combine(options, False)
        else:  # a leaf is decided by the prefix (horizon 0), so this is an unknown node
            raise STLError(f"unknown STL node {type(f).__name__}")
        self._memo[key] = out
        return out


def progress(formula: Formula, trace: Mapping[str, np.ndarray], regions: Mapping[str, ConvexPolygon], dt: float,
             k: int | None = None) -> Formula:
    """The formula for the rest of the trace after the prefix ``trace`` (samples 0..k), see the module doc.

    ``trace`` maps body name -> (N, 2) positions (m), sample j at time j * dt (s); ``k`` is the cut sample
    (default N - 1, the last one given; samples after k are ignored). The result is evaluated on the trace
    from sample k on, with sample k at time 0.

    A part of the formula whose samples all lie in the prefix becomes a :class:`Constant` leaf holding its
    robustness; windows still to come are shifted to start at the cut; a window that straddles the
    cut splits into its past samples (each progressed) and one shifted operator for its future ones:

    - ``F[a,b] g`` at sample j: ``Or(P(g, j+a) .. P(g, k-1), F[max(j+a,k)-k, j+b-k] g)``; ``G`` likewise with And;
    - ``l U[a,b] r`` at j: the past split points give ``And(P(r, t), P(l, j) .. P(l, t))`` for t < k, and the
      future ones ``And(P(l, j) .. P(l, k-1), l U[max(j+a,k)-k, j+b-k] r)``;
    - a boolean node progresses its children; a node evaluated at the cut itself is unchanged.

    Constants are folded as they appear (a min or max of constants is one constant), so a task whose temporal
    operators all sit at the top (the planner's fragment) progresses into the same fragment: the past of each
    ``G`` becomes one constant, a satisfied ``F`` window becomes one constant, and so on. Nested temporal
    operators progress exactly too, into one term per past sample that the prefix does not decide.
    """
    if not isinstance(formula, Formula):
        raise STLError(f"formula must be an STL Formula, got {type(formula).__name__}")
    dt = check_dt(dt)
    lengths = {len(np.asarray(v)) for name, v in trace.items() if name in formula.bodies()}
    n = min(lengths) if lengths else 1
    if n == 0:
        raise STLError("the trace prefix is empty; progression needs at least one sample")
    k = n - 1 if k is None else int(k)
    if not 0 <= k < n:
        raise STLError(f"cut sample k must be in 0..{n - 1} (the prefix has {n} samples), got {k}")
    prefix = {name: np.asarray(v, dtype=float)[:k + 1] for name, v in trace.items() if name in formula.bodies()}
    return _Progressor(formula, prefix, regions, dt, k).at(formula, 0)


def without_constants(formula: Formula) -> Formula | None:
    """The progressed task the planner flies the rest of the mission with: decided parts removed.

    A constant in a conjunction is dropped (the past cannot be changed, and a positive one would only cap
    the robustness the planner maximises); a disjunction with a non-negative constant is already satisfied
    (true), a negative constant in a disjunction is dropped. Returns None if nothing is left to plan for
    (the whole task is decided).
    """
    c = _const_value(formula)
    if c is not None:
        return None
    if isinstance(formula, (And, Or)):
        kids = [without_constants(ch) if _const_value(ch) is None else ch for ch in formula.children]
        if isinstance(formula, Or):
            if any((value := _const_value(ch)) is not None and value >= 0 for ch in formula.children):
                return None
        kept = [ch for ch in kids if ch is not None and _const_value(ch) is None]
        if not kept:
            return None
        return kept[0] if len(kept) == 1 else type(formula)(tuple(kept))
    if isinstance(formula, Not):
        inner = without_constants(formula.child)
        return None if inner is None else Not(inner)
    if isinstance(formula, (Eventually, Always)):
        inner = without_constants(formula.child)
        return None if inner is None else type(formula)(formula.a_s, formula.b_s, inner)
    if isinstance(formula, Until):
        left, right = without_constants(formula.left), without_constants(formula.right)
        if left is None or right is None:
            return None
        return Until(formula.a_s, formula.b_s, left, right)
    if isinstance(formula, InRegion):
        return formula
    return formula
