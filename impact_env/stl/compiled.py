"""The online STL monitor in C, for the formula classes the shipped tasks use: the numbers of
:class:`~impact_env.stl.monitor.OnlineMonitor`, bit for bit, in one call per sample.

The formulas it takes: predicates and any And/Or/Not of them (horizon 0), F[a, b] and G[a, b] over such a
formula, and And/Or of all these; in short every formula without nested temporal operators, without Until and
without a negated temporal operator. Every shipped task and every conjunct of one is of this class (e.g.
``F[0,100] in(O1, goal) & G[0,100] (!in(R1, W1) & ...)``). Then every temporal node is needed at t = 0 only, and
each holds at most one accumulator, one tentative value and one buffered final per child, so the C code
(``_cmonitor.c``) can mirror OnlineMonitor's own node list (compiled by :mod:`impact_env.stl.monitor`) node
for node, with the same comparisons in the same order. :func:`compiled_monitor` returns None for any other
formula, or when the extension is not built, and the caller uses OnlineMonitor.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from impact_env.errors import STLBindingError
from impact_env.geometry import ConvexPolygon
from impact_env.native import load
from impact_env.stl.formula import Formula
from impact_env.stl.monitor import OnlineMonitor, _Bool, _Node, _Not, _Static, _Window, checked_positions

_cmonitor = load("impact_env.stl._cmonitor", "the online STL monitor")

_STATIC, _NOT, _WINDOW, _BOOL = 0, 1, 2, 3  # node types of _cmonitor.c


class _NotCompilable(Exception):
    """The formula is outside the class the C monitor mirrors."""


def _tables(nodes: list[_Node], rows: Mapping[str, int]) -> tuple[np.ndarray, ...]:
    """OnlineMonitor's node list as the tables of _cmonitor.Monitor (nodes, preds, kids, regions, floats)."""
    index = {id(node): i for i, node in enumerate(nodes)}
    node_rows: list[list[int]] = []
    preds: list[tuple[int, int, int]] = []
    kids: list[tuple[int, int]] = []
    regions: list[tuple[int, int, int]] = []
    floats: list[float] = []
    region_index: dict[int, int] = {}

    def region_of(distance: Any) -> int:
        polygon = getattr(distance, "__self__", None)
        if not isinstance(polygon, ConvexPolygon) or distance.__func__ is not ConvexPolygon.signed_distance_xy:
            raise _NotCompilable("a predicate that is not a ConvexPolygon's signed distance")
        key = id(polygon)
        if key not in region_index:
            region_index[key] = len(regions)
            if polygon._box is not None:
                regions.append((1, len(floats), 0))
                floats.extend(polygon._box)
            else:
                regions.append((0, len(floats), len(polygon._edges_py)))
                for edge in polygon._edges_py:
                    floats.extend(edge)
        return region_index[key]

    for node in nodes:
        kind, is_and, a, b, child = _STATIC, 0, 0, 0, -1
        p0, k0 = len(preds), len(kids)
        if type(node) is _Static:
            is_and = int(node.is_and)
            for distance, body, negate in node.preds:
                preds.append((region_of(distance), rows[body], int(negate)))
            kids.extend((index[id(ch)], 0) for ch in node.kids)
        elif type(node) is _Not:
            kind, child = _NOT, index[id(node.child)]
            if node.child.h != 0:
                raise _NotCompilable("a negated temporal operator")
        elif type(node) is _Window:
            kind, is_and, a, b, child = _WINDOW, int(not node.is_max), node.a, node.b, index[id(node.child)]
            if node.child.h != 0 or node.lo != node.hi:
                raise _NotCompilable("nested temporal operators")
        elif type(node) is _Bool:
            kind, is_and = _BOOL, int(node.reduce is min)
            if node.lo != node.hi:
                raise _NotCompilable("nested temporal operators")
            kids.extend((index[id(ch)], int(buf is not None)) for ch, buf in node.pairs)
        else:
            raise _NotCompilable(f"a {type(node).__name__.lstrip('_')} node")
        node_rows.append([kind, node.lo, node.hi, node.h, is_and, a, b, child, p0, len(preds) - p0, k0,
                          len(kids) - k0])

    def table(items: list, cols: int, dtype: type) -> np.ndarray:
        return np.ascontiguousarray(np.array(items, dtype=dtype).reshape(-1, cols))

    return (table(node_rows, 12, np.int64), table(preds, 3, np.int64), table(kids, 2, np.int64),
            table(regions, 3, np.int64), np.array(floats, dtype=np.float64))


class CompiledMonitor:
    """:class:`~impact_env.stl.monitor.OnlineMonitor` in C: same arguments, same values, same errors.

    ``bodies`` gives the row of each body in the arrays passed to :meth:`update_rows` (the environment passes its
    state array, one row per body in scenario order); by default the formula's bodies in sorted order. Build
    one with :func:`compiled_monitor`, which says whether the formula is of the class this handles.
    """

    def __init__(self, formula: Formula, regions: Mapping[str, ConvexPolygon], dt: float,
                 bodies: Sequence[str] | None = None) -> None:
        if _cmonitor is None:
            raise _NotCompilable("the extension is not built")
        reference = OnlineMonitor(formula, regions, dt)  # every check of the arguments, and the node list
        self.formula, self.dt, self.regions = reference.formula, reference.dt, reference.regions
        self._bodies = reference._bodies
        self._horizon = reference.horizon_steps
        self._body_order = tuple(self._bodies if bodies is None else bodies)
        rows = {name: i for i, name in enumerate(self._body_order)}
        missing = [name for name in self._bodies if name not in rows]
        if missing:
            raise STLBindingError(f"formula names body {missing[0]!r} but the positions have "
                                  f"{', '.join(map(str, self._body_order)) or 'none'}")
        self._checked_rows = np.array([rows[name] for name in self._bodies], dtype=np.int64)
        self._c = _cmonitor.Monitor(*_tables(reference._nodes, rows), self._checked_rows, math.hypot)
        self._xy = np.zeros((len(self._body_order), 2))

    def __reduce__(self) -> tuple:
        if self.steps:
            raise TypeError("a compiled STL monitor can be pickled only before its first update")
        return CompiledMonitor, (self.formula, self.regions, self.dt, self._body_order)

    def reset(self) -> None:
        """Forget every sample (start of a new episode)."""
        self._c.reset()

    @property
    def value(self) -> float:
        """Robustness (m) of the samples so far (hold-last completed); NaN before the first update."""
        return self._c.value

    @property
    def steps(self) -> int:
        """Number of samples seen since the last reset."""
        return self._c.steps

    @property
    def horizon_steps(self) -> int:
        """Samples after which the value is final: it never changes once steps > horizon_steps."""
        return self._horizon

    @property
    def is_final(self) -> bool:
        """True once later samples can no longer change the value."""
        return self._c.is_final

    def live_state_size(self) -> int:
        """Number of floats held in accumulators, buffers and tentative values (bounded, independent of k)."""
        return self._c.live_state_size()

    def update(self, positions: Mapping[str, Sequence[float]]) -> float:
        """Append sample k = steps (body name -> (x, y) in m) and return the robustness of samples 0..k."""
        pos = checked_positions(self._bodies, positions)
        xy = self._xy
        for i, name in enumerate(self._body_order):
            if name in pos:
                xy[i] = pos[name]
        return self._c.update(xy, 2)

    def update_rows(self, xy: np.ndarray) -> float:
        """:meth:`update` from a C-contiguous float64 array, row ``i`` = ``bodies[i]``, x and y its first columns."""
        value = self._c.update(xy, xy.shape[1])
        if value is None:  # a position the formula reads is not finite: OnlineMonitor's error
            checked_positions(self._bodies, {name: (float(xy[i, 0]), float(xy[i, 1]))
                                             for i, name in enumerate(self._body_order)})
        return value


def compiled_monitor(formula: Formula, regions: Mapping[str, ConvexPolygon], dt: float,
                     bodies: Sequence[str] | None = None) -> CompiledMonitor | None:
    """A :class:`CompiledMonitor` if the extension is built and the formula is of its class, else None.

    Invalid arguments raise as OnlineMonitor would (STLError and its subclasses).
    """
    try:
        return CompiledMonitor(formula, regions, dt, bodies)
    except _NotCompilable:
        return None
