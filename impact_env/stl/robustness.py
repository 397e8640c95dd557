"""Offline quantitative semantics of STL (the paper's Eq. 2a-2d) on sampled position traces.

Why this package writes its own STL instead of using rtamt or stlpy: the same syntax tree must also be
compiled into mixed-integer constraints by the planner (so it has to be our own plain tree, not a monitor
library's internal AST); rtamt pins an old ANTLR runtime and does not install on Python >= 3.13; and using an
offline monitor for a dense reward means re-evaluating the whole prefix every step, O(T^2) over an episode,
whereas :class:`impact_env.stl.monitor.OnlineMonitor` updates in time independent of T.

Discrete time: sample k of a trace is at time k * dt. An interval [a, b] (s) covers the sample offsets
``interval_steps(a, b, dt)``. A trace of N >= 1 samples is completed by holding its last sample forever
("hold-last"), so every formula has a robustness on every non-empty trace; the robustness of the trace is
rho(0).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from impact_env.errors import STLBindingError, STLError
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
    interval_steps,
)


def _names(names: Iterable[object]) -> str:
    listed = ", ".join(str(n) for n in names)
    return listed if listed else "none"


def check_regions(formula: Formula, regions: Mapping[str, ConvexPolygon]) -> None:
    """Raise STLBindingError if the formula names a region that ``regions`` does not have."""
    for name in sorted(formula.regions()):
        if name not in regions:
            raise STLBindingError(f"formula names region {name!r} but the regions are {_names(regions)}")
        if not hasattr(regions[name], "signed_distance_xy"):
            raise STLError(f"region {name!r} must be a ConvexPolygon, got {type(regions[name]).__name__}")


def check_bodies(formula: Formula, available: Mapping[str, object], what: str = "the trace") -> None:
    """Raise STLBindingError if the formula names a body that ``available`` does not have."""
    for name in sorted(formula.bodies()):
        if name not in available:
            raise STLBindingError(f"formula names body {name!r} but {what} has {_names(available)}")


def _positions(formula: Formula, trace: Mapping[str, np.ndarray]) -> tuple[dict[str, np.ndarray], int]:
    """Validated (N, 2) float arrays of the bodies the formula reads, and N."""
    check_bodies(formula, trace)
    out: dict[str, np.ndarray] = {}
    length: int | None = None
    first = ""
    for name in sorted(formula.bodies()):
        p = np.asarray(trace[name], dtype=float)
        if p.ndim != 2 or p.shape[1] != 2:
            raise STLError(f"trace[{name!r}] must have shape (N, 2), got {p.shape}")
        if len(p) == 0:
            raise STLError(f"trace[{name!r}] is empty; robustness needs at least one sample")
        if not np.all(np.isfinite(p)):
            raise STLError(f"trace[{name!r}] contains NaN or infinite positions")
        if length is not None and len(p) != length:
            raise STLError(f"trace lengths differ: {first!r} has {length} samples but {name!r} has {len(p)}")
        length, first = len(p), name
        out[name] = p
    if length is None:  # no predicates at all (true/false): take the length from the trace itself
        lengths = {len(np.asarray(v)) for v in trace.values()}
        if len(lengths) > 1:
            raise STLError(f"trace lengths differ: {sorted(lengths)}")
        length = lengths.pop() if lengths else 1
        if length == 0:
            raise STLError("the trace is empty; robustness needs at least one sample")
    return out, length


def _window(signal: np.ndarray, a_k: int, b_k: int, maximum: bool) -> np.ndarray:
    """max (or min) of signal over [t + a_k, t + b_k] for every t, past the end holding the last value."""
    n = len(signal)
    padded = np.pad(signal, (0, b_k), mode="edge")
    windows = sliding_window_view(padded, b_k - a_k + 1)[a_k:a_k + n]  # row t covers t+a_k .. t+b_k
    return windows.max(axis=1) if maximum else windows.min(axis=1)


def _until(left: np.ndarray, right: np.ndarray, a_k: int, b_k: int) -> np.ndarray:
    """max_{j in [a_k, b_k]} min(right(t+j), min_{i in [0, j]} left(t+i)), by a loop over offsets j."""
    n = len(left)
    pl = np.pad(left, (0, b_k), mode="edge")
    pr = np.pad(right, (0, b_k), mode="edge")
    running = np.full(n, math.inf)  # min of left over [t, t + j]
    best = np.full(n, -math.inf)
    for j in range(b_k + 1):
        np.minimum(running, pl[j:j + n], out=running)
        if j >= a_k:
            np.maximum(best, np.minimum(running, pr[j:j + n]), out=best)
    return best


def _clamped(a_s: float, b_s: float, dt: float, n: int) -> tuple[int, int]:
    """The sample offsets of [a_s, b_s] capped at N - 1: past the end every child signal is constant (hold-last),
    so a window reaching beyond N - 1 has the value of one that ends there, and F[0, 1e20] costs no more than N.
    A bound too large to count in samples (F[0, 1e308] at dt = 0.1: 1e309 overflows) is capped before it is
    turned into an integer, so it too has a robustness."""
    if math.isfinite(b_s / dt):
        a_k, b_k = interval_steps(a_s, b_s, dt)
        return min(a_k, n - 1), min(b_k, n - 1)
    a_k = n - 1 if not math.isfinite(a_s / dt) else min(math.ceil(a_s / dt - 1e-9), n - 1)
    return a_k, n - 1


def _signal(f: Formula, pos: Mapping[str, np.ndarray], regions: Mapping[str, ConvexPolygon], dt: float,
            n: int) -> np.ndarray:
    # Every node's signal is computed on t = 0..N-1 only. Hold-last makes this exact: on the completed trace
    # every node's signal is constant for t >= N-1 (induction: predicates read a constant position; boolean
    # nodes combine constants; a window starting at t >= N-1 sees only constant child values). So the child
    # values a window needs beyond N-1 all equal the child's own value at N-1, i.e. edge padding at each level.
    if isinstance(f, InRegion):
        return np.asarray(regions[f.region].signed_distance(pos[f.body]), dtype=float)
    if isinstance(f, TrueFormula):
        return np.full(n, math.inf)
    if isinstance(f, Constant):
        return np.full(n, f.value)
    if isinstance(f, FalseFormula):
        return np.full(n, -math.inf)
    if isinstance(f, Not):
        return -_signal(f.child, pos, regions, dt, n)
    if isinstance(f, (And, Or)):
        stacked = np.stack([_signal(c, pos, regions, dt, n) for c in f.children])
        return stacked.min(axis=0) if isinstance(f, And) else stacked.max(axis=0)
    if isinstance(f, (Eventually, Always)):
        a_k, b_k = _clamped(f.a_s, f.b_s, dt, n)
        return _window(_signal(f.child, pos, regions, dt, n), a_k, b_k, maximum=isinstance(f, Eventually))
    if isinstance(f, Until):
        a_k, b_k = _clamped(f.a_s, f.b_s, dt, n)
        return _until(_signal(f.left, pos, regions, dt, n), _signal(f.right, pos, regions, dt, n), a_k, b_k)
    raise STLError(f"unknown STL node {type(f).__name__}")


def robustness_signal(formula: Formula, trace: Mapping[str, np.ndarray], regions: Mapping[str, ConvexPolygon],
                      dt: float) -> np.ndarray:
    """rho(t) (m) of the formula at every sample t = 0..N-1 of the hold-last completed trace, shape (N,).

    trace maps body name -> positions (N, 2) in metres, sample k at time k * dt (s); regions maps region name
    -> ConvexPolygon. Vectorised: windows are reductions over sliding views of edge-padded child signals.
    """
    if not isinstance(formula, Formula):
        raise STLError(f"formula must be an STL Formula (see impact_env.stl.parse), got {type(formula).__name__}")
    dt = check_dt(dt)
    check_regions(formula, regions)
    pos, n = _positions(formula, trace)
    return _signal(formula, pos, regions, dt, n)


def robustness(formula: Formula, trace: Mapping[str, np.ndarray], regions: Mapping[str, ConvexPolygon],
               dt: float) -> float:
    """Robustness rho(0) (m) of the hold-last completed trace: > 0 satisfies the formula, < 0 violates it."""
    return float(robustness_signal(formula, trace, regions, dt)[0])
