"""The online robustness of the stations' own tasks in O(1) per step: the same numbers as the STL monitor.

The generic :class:`~impact_env.stl.OnlineMonitor` handles any formula; a station's default tasks have one shape,
``F[0,T] G[0,H] psi`` ("reach, then hold for H"; ``H = 0`` is ``F[0,T] psi``, "eventually") with ``psi`` a
conjunction of predicates, and the environment evaluates it every control step. With the trace completed by
holding its last sample (the monitor's estimate), after sample ``k``:

- a window ``t <= k - H`` is final: ``g(t) = min rho[t .. t + H]``, a sliding-window minimum;
- a window ``k - H < t <= k`` reads only the held sample beyond ``k``: ``g(t) = min rho[t .. k]``, largest
  for the latest ``t``, that is ``rho(k)`` while ``k <= T`` and ``min rho[T .. k]`` after;
- the value is the largest ``g(t)`` over ``t in [0, T]``.

:class:`HoldMonitor` keeps the largest final window, the deque of the sliding minimum and the running minimum
from ``T``: constant time per sample. Its values are the generic monitor's, bit for bit (min and max of the same
predicate values; ``tests/impact_env/tether/test_fast_path.py`` compares them on random traces), and
:func:`task_monitor` falls back to the generic monitor for any other task. A conjunction's predicates are
evaluated boxes first; a polygon's is skipped when its 1-Lipschitz bound shows it cannot be the minimum.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping, Sequence

from impact_env.geometry import ConvexPolygon
from impact_env.stl import OnlineMonitor
from impact_env.stl.formula import Always, And, Eventually, Formula, InRegion, interval_steps


class HoldMonitor:
    """Online robustness of ``F[0,T] G[0,H] (p_1 & ... & p_n)`` or ``F[0,T] (p_1 & ...)`` (predicates ``in``).

    The interface of :class:`~impact_env.stl.OnlineMonitor` that the tether core uses: :meth:`reset`,
    :meth:`update` (body name -> (x, y)), :attr:`value`, :attr:`horizon_steps`.
    """

    def __init__(self, t_steps: int, h_steps: int, leaves: Sequence[InRegion],
                 regions: Mapping[str, ConvexPolygon]) -> None:
        self.t_steps, self.h_steps = t_steps, h_steps
        boxes, others = [], []
        for leaf in leaves:
            polygon = regions[leaf.region]
            if polygon._box is not None:
                boxes.append((leaf.body, polygon.signed_distance_xy))
            else:
                cx, cy = (float(c) for c in polygon.vertices.mean(axis=0))
                others.append((leaf.body, polygon.signed_distance_xy, cx, cy, polygon.signed_distance_xy(cx, cy)))
        self._boxes, self._others = boxes, others
        self._bodies = tuple(sorted({leaf.body for leaf in leaves}))
        self.reset()

    @property
    def horizon_steps(self) -> int:
        return self.t_steps + self.h_steps

    @property
    def value(self) -> float:
        return self._value

    def reset(self) -> None:
        self._k = -1
        self._window: deque[tuple[int, float]] = deque()  # (sample, rho), rho increasing: the sliding minimum
        self._best_final = -math.inf
        self._tail = math.inf  # min rho[T .. k]
        self._value = math.nan

    def _rho(self, positions: Mapping[str, Sequence[float]]) -> float:
        rho = math.inf
        for body, distance in self._boxes:
            p = positions[body]
            d = distance(p[0], p[1])
            if d < rho:
                rho = d
        for body, distance, cx, cy, depth in self._others:
            p = positions[body]
            # signed distances are 1-Lipschitz: this predicate is at least depth - |p - c|
            if rho <= depth - math.hypot(p[0] - cx, p[1] - cy):
                continue
            d = distance(p[0], p[1])
            if d < rho:
                rho = d
        return rho

    def update(self, positions: Mapping[str, Sequence[float]]) -> float:
        """Append the next sample and return the robustness of the trace so far (last sample held)."""
        return self._append(self._rho(positions))

    def update_pair(self, first: str, x0: float, y0: float, x1: float, y1: float) -> float:
        """:meth:`update` of a trace with two bodies, ``first`` at (x0, y0) and the other at (x1, y1) (no dict)."""
        rho = math.inf
        for body, distance in self._boxes:
            d = distance(x0, y0) if body == first else distance(x1, y1)
            if d < rho:
                rho = d
        for body, distance, cx, cy, depth in self._others:
            px, py = (x0, y0) if body == first else (x1, y1)
            if rho <= depth - math.hypot(px - cx, py - cy):
                continue
            d = distance(px, py)
            if d < rho:
                rho = d
        return self._append(rho)

    def _append(self, rho: float) -> float:
        k = self._k = self._k + 1
        if k >= self._k_final_end():
            return self._value  # every window is final: later samples change nothing
        window, h, t_end = self._window, self.h_steps, self.t_steps
        while window and window[-1][1] >= rho:
            window.pop()
        window.append((k, rho))
        start = k - h  # the window of t = k - H is complete now
        while window[0][0] < start:
            window.popleft()
        if 0 <= start <= t_end:
            lowest = window[0][1]
            if lowest > self._best_final:
                self._best_final = lowest
        if k >= t_end and rho < self._tail:
            self._tail = rho
        if k <= t_end:
            tentative = rho
        elif k < t_end + h:
            tentative = self._tail
        else:
            tentative = -math.inf
        self._value = tentative if tentative > self._best_final else self._best_final
        return self._value

    def _k_final_end(self) -> int:
        return self.t_steps + self.h_steps + 1


def hold_shape(formula: Formula, dt: float) -> tuple[int, int, list[InRegion]] | None:
    """(T, H, predicates) in samples if ``formula`` is ``F[0,T] G[0,H] conj`` or ``F[0,T] conj`` (``conj`` a
    predicate or a conjunction of predicates), else None."""
    if not isinstance(formula, Eventually) or formula.a_s != 0.0:
        return None
    inner, h = formula.child, 0
    if isinstance(inner, Always):
        if inner.a_s != 0.0:
            return None
        h = interval_steps(inner.a_s, inner.b_s, dt)[1]
        inner = inner.child
    leaves = list(inner.children) if isinstance(inner, And) else [inner]
    predicates = [leaf for leaf in leaves if isinstance(leaf, InRegion)]
    if len(predicates) != len(leaves):
        return None
    return interval_steps(formula.a_s, formula.b_s, dt)[1], h, predicates


def task_monitor(formula: Formula, regions: Mapping[str, ConvexPolygon], dt: float) -> HoldMonitor | OnlineMonitor:
    """The fast monitor for a task of the stations' shape, the generic one for any other."""
    generic = OnlineMonitor(formula, regions, dt)  # checks the formula, the regions and dt
    shape = hold_shape(formula, dt)
    if shape is None:
        return generic
    fast = HoldMonitor(shape[0], shape[1], shape[2], regions)
    return fast if fast.horizon_steps == generic.horizon_steps else generic
