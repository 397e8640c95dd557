"""Online STL robustness: one update per environment step, in time independent of the episode length.

:class:`OnlineMonitor` returns after samples 0..k exactly what
``robustness(formula, trace[:k+1], regions, dt)`` returns (the hold-last completion of the prefix), up to the
last bits of the scalar versus vectorised signed distance. Only min, max and negation act on those numbers.

How (a compiled node list fed final and tentative values per needed time) and what an update costs: see
:class:`OnlineMonitor`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence

from impact_env.errors import STLBindingError, STLError
from impact_env.geometry import ConvexPolygon
from impact_env.stl.formula import (
    Always,
    And,
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
from impact_env.stl.robustness import check_regions

_INF = math.inf
_NONE: tuple[float, ...] = ()  # "no tentative values"
_Positions = Mapping[str, tuple[float, float]]
_PredItem = tuple[Callable[[float, float], float], str, bool]  # (signed distance, body, negate)


class _Node:
    """A compiled node. lo..hi: needed times, h: horizon, last = hi + h: last step with any work (samples)."""

    __slots__ = ("lo", "hi", "h", "last", "c", "out", "ts", "tent")

    def __init__(self, lo: int, hi: int, h: int) -> None:
        self.lo, self.hi, self.h, self.last = lo, hi, h, hi + h
        self.c = math.nan  # value for t >= k
        self.out: float | None = None  # final value at k - h emitted this step
        self.ts = lo  # time of tent[0]
        self.tent: Sequence[float] = _NONE  # tentative values at needed t in (k - h, k)

    def step(self, k: int, pos: _Positions) -> None:
        raise NotImplementedError

    def state_size(self) -> int:
        return len(self.tent)


class _Not(_Node):
    __slots__ = ("child",)

    def __init__(self, child: _Node) -> None:
        super().__init__(child.lo, child.hi, child.h)
        self.child = child

    def step(self, k: int, pos: _Positions) -> None:
        ch = self.child
        self.c = -ch.c
        out = ch.out
        self.out = None if out is None else -out
        if ch.tent:
            self.ts, self.tent = ch.ts, [-v for v in ch.tent]
        else:
            self.tent = _NONE


class _Static(_Node):
    """And/Or whose children all have horizon 0, hence final at once; also a lone predicate or constant.

    Predicates (in(body, region) or its negation) are evaluated inline with the scalar signed distance,
    which saves a node call each in the common "avoid every wall" conjunction.
    """

    __slots__ = ("preds", "kids", "is_and")

    def __init__(self, lo: int, hi: int, preds: list[_PredItem], kids: list[_Node], is_and: bool) -> None:
        super().__init__(lo, hi, 0)
        self.preds, self.kids, self.is_and = tuple(preds), tuple(kids), is_and

    def step(self, k: int, pos: _Positions) -> None:
        if self.is_and:
            v = _INF
            for distance, body, negate in self.preds:
                x, y = pos[body]
                d = -distance(x, y) if negate else distance(x, y)
                if d < v:
                    v = d
            for ch in self.kids:
                if ch.c < v:
                    v = ch.c
        else:
            v = -_INF
            for distance, body, negate in self.preds:
                x, y = pos[body]
                d = -distance(x, y) if negate else distance(x, y)
                if d > v:
                    v = d
            for ch in self.kids:
                if ch.c > v:
                    v = ch.c
        self.c = v
        self.out = v if k >= self.lo else None


class _Bool(_Node):
    """And/Or with a temporal child; finals of children with a shorter horizon wait in a buffer."""

    __slots__ = ("children", "reduce", "buffers", "pairs")

    def __init__(self, lo: int, hi: int, children: list[_Node], is_and: bool) -> None:
        h = max(ch.h for ch in children)
        super().__init__(lo, hi, h)
        self.children = tuple(children)
        self.reduce = min if is_and else max
        self.buffers: tuple[dict[int, float] | None, ...] = tuple({} if ch.h < h else None for ch in children)
        self.pairs = tuple(zip(self.children, self.buffers, strict=True))

    def step(self, k: int, pos: _Positions) -> None:
        pairs, reduce = self.pairs, self.reduce
        if k <= self.hi:
            self.c = reduce([ch.c for ch in self.children])
        for ch, buf in pairs:
            if buf is not None and ch.out is not None:
                buf[k - ch.h] = ch.out
        tau = k - self.h
        self.out = None
        if tau >= self.lo:
            self.out = reduce([ch.out if buf is None else buf.pop(tau) for ch, buf in pairs])  # type: ignore
        t0, t1 = max(self.lo, tau + 1), min(self.hi, k - 1)
        if t0 > t1:
            self.tent = _NONE
            return
        self.ts = t0
        self.tent = [reduce([ch.tent[t - ch.ts] if buf is None or t > k - ch.h else buf[t] for ch, buf in pairs])
                     for t in range(t0, t1 + 1)]

    def state_size(self) -> int:
        return len(self.tent) + sum(len(b) for b in self.buffers if b is not None)


class _Window(_Node):
    """F[a, b] (is_max) or G[a, b] with b >= 1 samples."""

    __slots__ = ("child", "a", "b", "is_max", "accs", "acc_t0")

    def __init__(self, lo: int, hi: int, child: _Node, a: int, b: int, is_max: bool) -> None:
        super().__init__(lo, hi, b + child.h)
        self.child, self.a, self.b, self.is_max = child, a, b, is_max
        self.accs: list[float] = []  # accs[i]: max/min of the child finals so far in the window of acc_t0 + i
        self.acc_t0 = lo

    def step(self, k: int, pos: _Positions) -> None:
        ch, a, b, lo, hi, is_max, accs = self.child, self.a, self.b, self.lo, self.hi, self.is_max, self.accs
        if k <= hi:
            self.c = ch.c
        v = ch.out
        self.out = None
        if v is not None:  # child final at tau = k - h_child
            tau = k - ch.h
            if lo <= tau - a <= hi:
                accs.append(v)  # first value in the window of t = tau - a
            for i, acc in enumerate(accs):
                if (v > acc) if is_max else (v < acc):
                    accs[i] = v
            if tau - b == self.acc_t0:  # window of t = tau - b is complete
                self.out = accs.pop(0)
                self.acc_t0 += 1
        t0, t1 = max(lo, k - self.h + 1), min(hi, k - 1)
        if t0 > t1:
            self.tent = _NONE
            return
        reduce = max if is_max else min
        fin, ct, cts, c_child = k - ch.h, ch.tent, ch.ts, ch.c
        tent = []
        for t in range(t0, t1 + 1):
            best = accs[t - self.acc_t0] if t + a <= fin else (-_INF if is_max else _INF)
            s = t + a if t + a > fin else fin + 1  # child tentative part of the window: s..e
            e = t + b if t + b < k else k - 1
            if s <= e:
                best = reduce(best, reduce(ct[s - cts:e - cts + 1]))
            if t + b >= k:  # the window reaches the held last sample
                best = reduce(best, c_child)
            tent.append(best)
        self.ts, self.tent = t0, tent

    def state_size(self) -> int:
        return len(self.tent) + len(self.accs)


class _Until(_Node):
    """left U[a, b] right with b >= 1 samples."""

    __slots__ = ("left", "right", "a", "b", "hm", "buf_left", "buf_right", "runs", "bests", "acc_t0")

    def __init__(self, lo: int, hi: int, left: _Node, right: _Node, a: int, b: int) -> None:
        hm = max(left.h, right.h)
        super().__init__(lo, hi, b + hm)
        self.left, self.right, self.a, self.b, self.hm = left, right, a, b, hm
        self.buf_left: dict[int, float] = {}
        self.buf_right: dict[int, float] = {}
        self.runs: list[float] = []  # runs[i]: min of left over [t, tau] for t = acc_t0 + i
        self.bests: list[float] = []  # bests[i]: max over tau' in [t + a, tau] of min(right(tau'), run)
        self.acc_t0 = lo

    def step(self, k: int, pos: _Positions) -> None:
        L, R, a, b, lo, hi, hm = self.left, self.right, self.a, self.b, self.lo, self.hi, self.hm
        runs, bests, buf_l, buf_r = self.runs, self.bests, self.buf_left, self.buf_right
        if k <= hi:
            self.c = min(L.c, R.c)
        if L.h < hm and L.out is not None:
            buf_l[k - L.h] = L.out
        if R.h < hm and R.out is not None:
            buf_r[k - R.h] = R.out
        self.out = None
        tau = k - hm  # both children are final up to tau
        if tau >= lo:
            # both children have a value for tau (out is None only before a child's first); rv is None before
            # lo + a, where it is never read
            lv: float = L.out if L.h == hm else buf_l.pop(tau)  # type: ignore[assignment]
            rv: float = R.out if R.h == hm else buf_r.pop(tau, None)  # type: ignore[assignment, arg-type]
            if tau <= hi:
                runs.append(_INF)
                bests.append(-_INF)
            t = self.acc_t0
            for i in range(len(runs)):
                run = runs[i]
                if lv < run:
                    run = runs[i] = lv
                if tau >= t + i + a:
                    m = rv if rv < run else run
                    if m > bests[i]:
                        bests[i] = m
            if tau - b == self.acc_t0:
                self.out = bests.pop(0)
                runs.pop(0)
                self.acc_t0 += 1
        t0, t1 = max(lo, k - self.h + 1), min(hi, k - 1)
        if t0 > t1:
            self.tent = _NONE
            return
        fin_l, fin_r = k - L.h, k - R.h
        tent = []
        for t in range(t0, t1 + 1):
            if t <= tau:
                run, best = runs[t - self.acc_t0], bests[t - self.acc_t0]
            else:
                run, best = _INF, -_INF
            # sample k stands for every tau' >= k (held last sample), so the loop stops there
            for sg in range(min(max(t, tau + 1), k), min(t + b, k) + 1):
                at_k = sg == k
                lv = L.c if at_k else (buf_l[sg] if sg <= fin_l else L.tent[sg - L.ts])
                if lv < run:
                    run = lv
                if at_k or sg >= t + a:
                    rv = R.c if at_k else (buf_r[sg] if sg <= fin_r else R.tent[sg - R.ts])
                    best = max(best, min(rv, run))
            tent.append(best)
        self.ts, self.tent = t0, tent

    def state_size(self) -> int:
        return len(self.tent) + 2 * len(self.runs) + len(self.buf_left) + len(self.buf_right)


def _pred_item(f: Formula, regions: Mapping[str, ConvexPolygon]) -> _PredItem | None:
    """(distance, body, negate) if f is in(body, region) or its negation, else None."""
    negate = isinstance(f, Not)
    if negate:
        f = f.child  # type: ignore[attr-defined]
    if isinstance(f, InRegion):
        return regions[f.region].signed_distance_xy, f.body, negate
    return None


def _compile(f: Formula, lo: int, hi: int, dt: float, regions: Mapping[str, ConvexPolygon],
             nodes: list[_Node]) -> _Node:
    """Compile f, needed on [lo, hi] (samples), appending its nodes to ``nodes`` children first."""
    node: _Node
    item = _pred_item(f, regions)
    if item is not None:
        node = _Static(lo, hi, [item], [], True)
    elif isinstance(f, (TrueFormula, FalseFormula)):  # the empty And is +inf, the empty Or -inf
        node = _Static(lo, hi, [], [], isinstance(f, TrueFormula))
    elif isinstance(f, Not):
        node = _Not(_compile(f.child, lo, hi, dt, regions, nodes))
    elif isinstance(f, (And, Or)):
        node = _boolean(list(f.children), isinstance(f, And), lo, hi, dt, regions, nodes)
    elif isinstance(f, (Eventually, Always)):
        a, b = interval_steps(f.a_s, f.b_s, dt)
        if b == 0:  # F[0,0] phi = G[0,0] phi = phi
            return _compile(f.child, lo, hi, dt, regions, nodes)
        child = _compile(f.child, lo + a, hi + b, dt, regions, nodes)
        node = _Window(lo, hi, child, a, b, isinstance(f, Eventually))
    elif isinstance(f, Until):
        a, b = interval_steps(f.a_s, f.b_s, dt)
        if b == 0:  # phi U[0,0] psi = phi & psi
            node = _boolean([f.left, f.right], True, lo, hi, dt, regions, nodes)
        else:
            left = _compile(f.left, lo, hi + b, dt, regions, nodes)
            right = _compile(f.right, lo + a, hi + b, dt, regions, nodes)
            node = _Until(lo, hi, left, right, a, b)
    else:
        raise STLError(f"unknown STL node {type(f).__name__}")
    nodes.append(node)
    return node


def _boolean(children: list[Formula], is_and: bool, lo: int, hi: int, dt: float,
             regions: Mapping[str, ConvexPolygon], nodes: list[_Node]) -> _Node:
    """And (is_and) or Or of children: one _Static node if all have horizon 0, else a _Bool node."""
    if all(horizon_steps(c, dt) == 0 for c in children):
        items = [_pred_item(c, regions) for c in children]
        preds = [item for item in items if item is not None]
        kids = [_compile(c, lo, hi, dt, regions, nodes) for c, item in zip(children, items, strict=True)
                if item is None]
        return _Static(lo, hi, preds, kids, is_and)
    return _Bool(lo, hi, [_compile(c, lo, hi, dt, regions, nodes) for c in children], is_and)


class OnlineMonitor:
    """Robustness (m) of the trace so far, one sample per :meth:`update`, equal to the offline robustness.

    formula: the STL formula; regions: region name -> ConvexPolygon; dt: period between samples (s).

    Algorithm. The formula is compiled into a flat list of small node objects, children before parents. Times
    and intervals are in samples; node n has horizon h_n and, after sample k,

    * NEEDED interval [lo_n, hi_n]: the times its parent reads. The root is needed at t = 0 only; the child of
      F/G[a, b] whose parent is needed on [lo, hi] is needed on [lo + a, hi + b]; U's left child on [lo, hi + b]
      and its right child on [lo + a, hi + b]; Not/And/Or pass the interval through.
    * FINAL values at t <= k - h_n: they read only real samples and never change again. Each step a node emits
      (``out``) its one new final value, at tau = k - h_n, if tau is needed.
    * TENTATIVE values at k - h_n < t < k: they read the hold-last completion. Each step a node recomputes them
      (``tent``, starting at time ``ts``), for needed t only.
    * the CONSTANT c_n for t >= k: the node evaluated atemporally on sample k (a temporal operator on a constant
      signal is its child, U is min(c_left, c_right)).

    F/G[a, b] keep one running max/min per needed t whose window [t + a, t + b] has started receiving final child
    values; each new child final at tau updates the live accumulators (t in [tau - b, tau - a]) and, when
    tau = t + b, the accumulator of t is the final value of t and is emitted and dropped. A tentative value is
    the accumulator (child finals in the window), combined with the child's tentative values in the window and
    c_child if the window reaches k. U[a, b] does the same with the pair (running min of left over [t, tau],
    best so far), fed with (left, right) finals in step; the child with the shorter horizon is buffered until
    the other catches up, as are the faster children of And/Or. Nothing is kept for times no parent needs, and a
    node stops working once its last needed time is final (k > hi_n + h_n); once the root is final, updates are
    O(number of bodies).

    Cost per update. Predicates, and And/Or/Not over them, have horizon 0: always final, no tentative values,
    O(1) each. An F/G node costs O(L + |T| * min(b - a + 1, h_child)) and a U node O(L + |T| * (b + 1)), where
    L <= min(hi - lo + 1, window) is its number of live accumulators and |T| <= min(hi - lo + 1, h_n - 1) its
    number of needed tentative times. Both are bounded by the nested window lengths, never by k. For formulas
    without nested temporal operators, e.g. ``F[0,100] in(O1,goal) & G[0,100] (!in(R1,W1) & !in(R2,W2))``, every
    temporal node is needed at t = 0 only, so L <= 1, |T| <= 1 and an update is O(number of nodes).
    """

    def __init__(self, formula: Formula, regions: Mapping[str, ConvexPolygon], dt: float) -> None:
        if not isinstance(formula, Formula):
            raise STLError(f"formula must be an STL Formula (see impact_env.stl.parse), got {type(formula).__name__}")
        self.formula = formula
        self.dt = check_dt(dt)
        check_regions(formula, regions)
        self.regions = dict(regions)
        self._bodies = tuple(sorted(formula.bodies()))
        self._horizon = horizon_steps(formula, self.dt)  # raises STLError for an interval without samples
        self.reset()

    def reset(self) -> None:
        """Forget every sample (start of a new episode)."""
        self._nodes: list[_Node] = []
        self._root = _compile(self.formula, 0, 0, self.dt, self.regions, self._nodes)
        self._steps = 0
        self._value = math.nan
        self._final: float | None = None

    @property
    def value(self) -> float:
        """Robustness (m) of the samples so far (hold-last completed); NaN before the first update."""
        return self._value

    @property
    def steps(self) -> int:
        """Number of samples seen since the last reset."""
        return self._steps

    @property
    def horizon_steps(self) -> int:
        """Samples after which the value is final: it never changes once steps > horizon_steps."""
        return self._horizon

    @property
    def is_final(self) -> bool:
        """True once later samples can no longer change the value."""
        return self._final is not None

    def live_state_size(self) -> int:
        """Number of floats held in accumulators, buffers and tentative values (bounded, independent of k)."""
        return sum(node.state_size() for node in self._nodes)

    def update(self, positions: Mapping[str, Sequence[float]]) -> float:
        """Append sample k = steps (body name -> (x, y) in m) and return the robustness of samples 0..k."""
        pos = checked_positions(self._bodies, positions)
        k = self._steps
        if self._final is None:
            for node in self._nodes:
                if k <= node.last:
                    node.step(k, pos)
                else:  # finished: its last final must not be read again
                    node.out = None
            root = self._root
            if root.out is not None:
                self._final = self._value = root.out
            else:
                self._value = root.tent[0] if root.tent else root.c
        self._steps = k + 1
        return self._value


def checked_positions(bodies: Sequence[str],
                      positions: Mapping[str, Sequence[float]]) -> dict[str, tuple[float, float]]:
    """``bodies``' positions as (x, y) floats; STLBindingError for a missing body, STLError for a bad or
    non-finite position."""
    pos: dict[str, tuple[float, float]] = {}
    for name in bodies:
        if name not in positions:
            raise STLBindingError(f"formula names body {name!r} but the positions have "
                                  f"{', '.join(map(str, positions)) or 'none'}")
        p = positions[name]
        try:
            x, y = p[0], p[1]
            if type(x) is not float or type(y) is not float:
                x, y = float(x), float(y)
        except (TypeError, ValueError, IndexError, KeyError):
            raise STLError(f"positions[{name!r}] must be (x, y) in metres, got {p!r}") from None
        if x - x != 0.0 or y - y != 0.0:  # NaN or infinite
            raise STLError(f"positions[{name!r}] must be finite, got ({x}, {y})")
        pos[name] = (x, y)
    return pos
