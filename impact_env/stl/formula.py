"""The STL syntax tree (the paper's Eq. 2a-2d): predicates, boolean connectives, bounded temporal operators.

One frozen dataclass per node, plain data in the style of stlpy: every node exposes ``children`` (a tuple of
sub-formulas, empty for leaves), so the robustness evaluator, the online monitor and the MILP planner all walk
the same tree; the tree itself knows nothing about solvers or traces. Interval bounds are in seconds;
:func:`interval_steps` and :func:`horizon_steps` turn them into sample indices for a control period ``dt``.

``str(formula)`` prints text that :func:`impact_env.stl.parse` reads back into an equal tree, for every node
but :class:`Constant`, the leaf that STL progression (:mod:`impact_env.stl.progression`) leaves behind for
the past: it has no syntax of its own (its text ``const(0.25)`` is for reading only).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

from impact_env.errors import STLError

_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
_EPS = 1e-9  # tolerance, in samples, for interval bounds that are a multiple of dt up to rounding

# printing precedence, loosest first: | & U prefix atom (see parser.py for the grammar)
_OR, _AND, _UNTIL, _PREFIX, _ATOM = 1, 2, 3, 4, 5


def _fmt(x: float) -> str:
    """Shortest text of a bound that parses back to the same float: 100 rather than 100.0."""
    return str(int(x)) if x == int(x) and abs(x) < 1e15 else repr(x)


def _wrap(f: Formula, min_prec: int) -> str:
    text = f._text()
    return text if f._prec >= min_prec else f"({text})"


def _check_interval(a_s: float, b_s: float, op: str) -> tuple[float, float]:
    a, b = float(a_s), float(b_s)
    if not (math.isfinite(a) and math.isfinite(b)):
        raise STLError(f"{op}[{a_s}, {b_s}]: interval bounds must be finite seconds")
    if a < 0.0 or a > b:
        raise STLError(f"{op}[{a_s}, {b_s}]: interval must satisfy 0 <= a <= b (seconds)")
    return a, b


def _check_formula(x: object, where: str) -> None:
    if not isinstance(x, Formula):
        raise STLError(f"{where} must be an STL Formula, got {type(x).__name__}")


class Formula:
    """Base class of STL formulas. Combine with ``&``, ``|``, ``~`` (not) and :meth:`until`."""

    _prec: ClassVar[int] = _ATOM

    if TYPE_CHECKING:
        # every node has ``children`` (a field of And/Or, a property elsewhere); it is declared for the type
        # checker only, because a base-class property would become the dataclass default of And.children
        @property
        def children(self) -> tuple[Formula, ...]: ...

    @property
    def horizon_s(self) -> float:
        """How far (s) into the future the formula looks from the time it is evaluated at."""
        raise NotImplementedError

    def bodies(self) -> frozenset[str]:
        """Names of the bodies whose positions the formula reads."""
        return frozenset().union(*(c.bodies() for c in self.children))

    def regions(self) -> frozenset[str]:
        """Names of the regions the formula refers to."""
        return frozenset().union(*(c.regions() for c in self.children))

    def until(self, other: Formula, a_s: float, b_s: float) -> Until:
        """``self U[a_s, b_s] other``."""
        return Until(a_s, b_s, self, other)

    def __and__(self, other: object) -> Formula:
        if not isinstance(other, Formula):
            return NotImplemented
        left = self.children if type(self) is And else (self,)
        right = other.children if type(other) is And else (other,)
        return And(left + right)

    def __or__(self, other: object) -> Formula:
        if not isinstance(other, Formula):
            return NotImplemented
        left = self.children if type(self) is Or else (self,)
        right = other.children if type(other) is Or else (other,)
        return Or(left + right)

    def __invert__(self) -> Formula:
        return Not(self)

    def __str__(self) -> str:
        return self._text()

    def _text(self) -> str:
        raise NotImplementedError


@dataclass(frozen=True, eq=True)
class TrueFormula(Formula):
    """The constant true; robustness +inf."""

    @property
    def children(self) -> tuple[Formula, ...]:
        return ()

    @property
    def horizon_s(self) -> float:
        return 0.0

    def _text(self) -> str:
        return "true"


@dataclass(frozen=True, eq=True)
class FalseFormula(Formula):
    """The constant false; robustness -inf."""

    @property
    def children(self) -> tuple[Formula, ...]:
        return ()

    @property
    def horizon_s(self) -> float:
        return 0.0

    def _text(self) -> str:
        return "false"


@dataclass(frozen=True, eq=True)
class Constant(Formula):
    """A leaf of known robustness ``value`` (m) at every time: what a part of a formula that the past already
    decided contributes (see :mod:`impact_env.stl.progression`). Not part of the text syntax."""

    value: float

    def __post_init__(self) -> None:
        try:
            value = float(self.value)
        except (TypeError, ValueError):
            raise STLError(f"Constant(value) must be a number of metres, got {self.value!r}") from None
        if math.isnan(value):
            raise STLError("Constant(value) must not be NaN")
        object.__setattr__(self, "value", value)

    @property
    def children(self) -> tuple[Formula, ...]:
        return ()

    @property
    def horizon_s(self) -> float:
        return 0.0

    def _text(self) -> str:
        return f"const({self.value!r})"


@dataclass(frozen=True, eq=True)
class InRegion(Formula):
    """Predicate "body is in region"; robustness = signed distance (m) of the body to the region, + inside."""

    body: str
    region: str

    def __post_init__(self) -> None:
        for what, name in (("body", self.body), ("region", self.region)):
            if not isinstance(name, str) or not _NAME.match(name):
                raise STLError(f"in(BODY, REGION): {what} name must match [A-Za-z_][A-Za-z0-9_]*, got {name!r}")

    @property
    def children(self) -> tuple[Formula, ...]:
        return ()

    @property
    def horizon_s(self) -> float:
        return 0.0

    def bodies(self) -> frozenset[str]:
        return frozenset((self.body,))

    def regions(self) -> frozenset[str]:
        return frozenset((self.region,))

    def _text(self) -> str:
        return f"in({self.body}, {self.region})"


@dataclass(frozen=True, eq=True)
class Not(Formula):
    """Negation; robustness -rho(child)."""

    child: Formula
    _prec: ClassVar[int] = _PREFIX

    def __post_init__(self) -> None:
        _check_formula(self.child, "Not(child)")

    @property
    def children(self) -> tuple[Formula, ...]:
        return (self.child,)

    @property
    def horizon_s(self) -> float:
        return self.child.horizon_s

    def _text(self) -> str:
        return "!" + _wrap(self.child, _PREFIX)


@dataclass(frozen=True, eq=True)
class _NAry(Formula):
    """Shared body of And and Or (n-ary, at least two children)."""

    children: tuple[Formula, ...]
    _symbol: ClassVar[str] = ""

    def __post_init__(self) -> None:
        kids = tuple(self.children)
        name = type(self).__name__
        if len(kids) < 2:
            raise STLError(f"{name} needs at least 2 children, got {len(kids)}; use the formula itself instead")
        for i, c in enumerate(kids):
            _check_formula(c, f"{name}.children[{i}]")
        object.__setattr__(self, "children", kids)

    @property
    def horizon_s(self) -> float:
        return max(c.horizon_s for c in self.children)

    def _text(self) -> str:
        return f" {self._symbol} ".join(_wrap(c, self._prec + 1) for c in self.children)


@dataclass(frozen=True, eq=True)
class And(_NAry):
    """Conjunction of two or more formulas; robustness = min over children."""

    _prec: ClassVar[int] = _AND
    _symbol: ClassVar[str] = "&"


@dataclass(frozen=True, eq=True)
class Or(_NAry):
    """Disjunction of two or more formulas; robustness = max over children."""

    _prec: ClassVar[int] = _OR
    _symbol: ClassVar[str] = "|"


@dataclass(frozen=True, eq=True)
class _Bounded(Formula):
    """Shared body of Eventually and Always: a unary temporal operator over [a_s, b_s] seconds."""

    a_s: float
    b_s: float
    child: Formula
    _prec: ClassVar[int] = _PREFIX
    _symbol: ClassVar[str] = ""

    def __post_init__(self) -> None:
        a, b = _check_interval(self.a_s, self.b_s, self._symbol)
        object.__setattr__(self, "a_s", a)
        object.__setattr__(self, "b_s", b)
        _check_formula(self.child, f"{type(self).__name__}.child")

    @property
    def children(self) -> tuple[Formula, ...]:
        return (self.child,)

    @property
    def horizon_s(self) -> float:
        return self.b_s + self.child.horizon_s

    def _text(self) -> str:
        return f"{self._symbol}[{_fmt(self.a_s)}, {_fmt(self.b_s)}] {_wrap(self.child, _PREFIX)}"


@dataclass(frozen=True, eq=True)
class Eventually(_Bounded):
    """F[a_s, b_s] child: child holds at some time in [t + a_s, t + b_s]; robustness = max over the window."""

    _symbol: ClassVar[str] = "F"


@dataclass(frozen=True, eq=True)
class Always(_Bounded):
    """G[a_s, b_s] child: child holds at every time in [t + a_s, t + b_s]; robustness = min over the window."""

    _symbol: ClassVar[str] = "G"


@dataclass(frozen=True, eq=True)
class Until(Formula):
    """left U[a_s, b_s] right: right holds at some tau in [t + a_s, t + b_s] and left holds on all of [t, tau].

    Robustness: max over tau in [t+a, t+b] of min(rho_right(tau), min over sigma in [t, tau] of rho_left(sigma)),
    with the closed interval [t, tau] (left must also hold at tau itself).
    """

    a_s: float
    b_s: float
    left: Formula
    right: Formula
    _prec: ClassVar[int] = _UNTIL

    def __post_init__(self) -> None:
        a, b = _check_interval(self.a_s, self.b_s, "U")
        object.__setattr__(self, "a_s", a)
        object.__setattr__(self, "b_s", b)
        _check_formula(self.left, "Until.left")
        _check_formula(self.right, "Until.right")

    @property
    def children(self) -> tuple[Formula, ...]:
        return (self.left, self.right)

    @property
    def horizon_s(self) -> float:
        return self.b_s + max(self.left.horizon_s, self.right.horizon_s)

    def _text(self) -> str:
        # U is non-associative in the grammar, so an Until operand is parenthesised
        return f"{_wrap(self.left, _PREFIX)} U[{_fmt(self.a_s)}, {_fmt(self.b_s)}] {_wrap(self.right, _PREFIX)}"


def conjuncts(formula: Formula) -> tuple[Formula, ...]:
    """The formula as a conjunction of as many parts as possible: rho(formula) = min over the parts.

    Flattens nested And and distributes Always over And, G[a, b] (p & q) = G[a, b] p & G[a, b] q, an identity
    of robustness too (min over the window commutes with min over the children). A formula that is not a
    conjunction is its own single part.
    """
    if isinstance(formula, And):
        return tuple(part for child in formula.children for part in conjuncts(child))
    if isinstance(formula, Always) and isinstance(formula.child, And):
        return tuple(Always(formula.a_s, formula.b_s, part) for part in conjuncts(formula.child))
    return (formula,)


def check_dt(dt: float) -> float:
    """Validate a sampling period dt (s) and return it as a float."""
    try:
        value = float(dt)
    except (TypeError, ValueError):
        raise STLError(f"dt must be a number of seconds, got {dt!r}") from None
    if not (math.isfinite(value) and value > 0.0):
        raise STLError(f"dt must be a finite number of seconds > 0, got {dt!r}")
    return value


def interval_steps(a_s: float, b_s: float, dt: float) -> tuple[int, int]:
    """Sample offsets (a_k, b_k) covered by the interval [a_s, b_s] (s) at period dt (s).

    a_k = ceil(a_s/dt), b_k = floor(b_s/dt), both up to 1e-9 samples of rounding slack. Raises STLError if
    the interval contains no sample.
    """
    dt = check_dt(dt)
    if not math.isfinite(b_s / dt):  # e.g. F[0, 1e308] at dt = 0.1: more samples than a float can count
        raise STLError(f"interval [{_fmt(a_s)}, {_fmt(b_s)}] s is too long for dt = {dt} s ({b_s!r} / {dt!r} "
                       "overflows); no trace is that long: use a bound within the task's horizon")
    a_k = math.ceil(a_s / dt - _EPS)
    b_k = math.floor(b_s / dt + _EPS)
    if a_k > b_k:
        raise STLError(f"interval [{_fmt(a_s)}, {_fmt(b_s)}] s contains no sample at dt = {dt} s; "
                       f"widen it to include a multiple of {dt}")
    return a_k, b_k


def horizon_steps(formula: Formula, dt: float) -> int:
    """Horizon of the formula in samples at period dt (s): how many samples after t its value at t reads."""
    if isinstance(formula, _Bounded):
        return interval_steps(formula.a_s, formula.b_s, dt)[1] + horizon_steps(formula.child, dt)
    if isinstance(formula, Until):
        b_k = interval_steps(formula.a_s, formula.b_s, dt)[1]
        return b_k + max(horizon_steps(formula.left, dt), horizon_steps(formula.right, dt))
    return max((horizon_steps(c, dt) for c in formula.children), default=0)
