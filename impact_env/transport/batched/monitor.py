"""Batched online STL robustness: the scalar monitor's recurrences as tensor ops over the env axis.

Supported class: any Boolean combination (``&``, ``|``, ``!``) of temporal operators ``F[a,b]``, ``G[a,b]``
and ``U[a,b]`` whose operands have no temporal operator of their own, and of atemporal formulas (read at
t = 0). All seven shipped tasks are of this kind. Every temporal node is then needed at t = 0 only, and
after samples 0..k its value with the last sample held (what :class:`~impact_env.stl.OnlineMonitor`
returns) has a closed form. With c_k the child's robustness at sample k:

* ``F[a,b]``: acc_k = max of c_j over j in [a, min(k, b)]; value_k = acc_k if k >= a, else c_k (every time
  of the window is still in the future, where the held sample k stands for the trace). ``G``: min.
* ``l U[a,b] r``: run_k = min of l_j over j in [0, min(k, b)], best_k = max over tau in [a, min(k, b)] of
  min(r_tau, run_tau); value_k = best_k if k >= a, else min(r_k, run_k).
* an atemporal formula at the root: its value at sample 0, i.e. F[0,0].

Only min, max and negation act on the signed distances, so the values equal the scalar monitor's up to
the last bits of the distances (float64) or float32 rounding of the positions (float32). Nested temporal
operators (e.g. ``F[0,10] G[0,5] p``) raise :class:`~impact_env.errors.STLUnsupportedError` when the monitor
is built, never a wrong value.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import torch

from impact_env.errors import STLBindingError, STLUnsupportedError
from impact_env.geometry import ConvexPolygon, Edge
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
from impact_env.stl.robustness import check_regions
from impact_env.transport.batched.physics import TensorKwargs

# (window accumulators [W, N], until running minima [U, N], until bests [U, N])
MonitorState = tuple[torch.Tensor, torch.Tensor, torch.Tensor]
_INF = float("inf")
# an atemporal expression: ("pred", row, sign) | ("const", value) | ("min"|"max", children)
_Expr = tuple


@dataclass(frozen=True)
class _Window:
    """F (is_max) or G over [a, b] samples of an atemporal child, needed at t = 0."""

    child: _Expr
    a: int
    b: int
    is_max: bool


@dataclass(frozen=True)
class _UntilNode:
    left: _Expr
    right: _Expr
    a: int
    b: int


def _horizon_free(f: Formula) -> bool:
    return not isinstance(f, (Eventually, Always, Until)) and all(_horizon_free(c) for c in f.children)


class _Compiler:
    """Turns formulas into expressions over predicate rows, window nodes and until nodes."""

    def __init__(self, regions: Mapping[str, ConvexPolygon], body_index: Mapping[str, int], dt: float) -> None:
        self.regions, self.body_index, self.dt = regions, body_index, dt
        self.preds: list[tuple[int, str]] = []  # (body index, region name)
        self.windows: list[_Window] = []
        self.untils: list[_UntilNode] = []

    def _pred(self, f: InRegion) -> int:
        if f.body not in self.body_index:
            raise STLBindingError(f"formula names body {f.body!r} but the world has {', '.join(self.body_index)}")
        key = (self.body_index[f.body], f.region)
        if key not in self.preds:
            self.preds.append(key)
        return self.preds.index(key)

    def atemporal(self, f: Formula, where: Formula) -> _Expr:
        if isinstance(f, InRegion):
            return ("pred", self._pred(f), 1.0)
        if isinstance(f, TrueFormula):
            return ("const", _INF)
        if isinstance(f, FalseFormula):
            return ("const", -_INF)
        if isinstance(f, Constant):
            return ("const", f.value)
        if isinstance(f, Not):
            return _negate(self.atemporal(f.child, where))
        if isinstance(f, (And, Or)):
            return ("min" if isinstance(f, And) else "max", tuple(self.atemporal(c, where) for c in f.children))
        raise STLUnsupportedError(f"the batched monitor supports temporal operators whose operands have no temporal "
                                  f"operator; {where} nests {f} inside it (use the scalar OnlineMonitor, i.e. the "
                                  "pymunk environments, for this task)")

    def root(self, f: Formula) -> _Expr:
        """An expression over temporal node values ("window", i) / ("until", i) for the formula at t = 0."""
        if _horizon_free(f):
            return self._window(self.atemporal(f, f), 0, 0, True)
        if isinstance(f, Not):
            return _negate(self.root(f.child))
        if isinstance(f, (And, Or)):
            return ("min" if isinstance(f, And) else "max", tuple(self.root(c) for c in f.children))
        if isinstance(f, (Eventually, Always)):
            a, b = interval_steps(f.a_s, f.b_s, self.dt)
            return self._window(self.atemporal(f.child, f), a, b, isinstance(f, Eventually))
        if isinstance(f, Until):
            a, b = interval_steps(f.a_s, f.b_s, self.dt)
            left, right = self.atemporal(f.left, f), self.atemporal(f.right, f)
            if b == 0:  # phi U[0,0] psi = phi & psi
                return self._window(("min", (left, right)), 0, 0, True)
            self.untils.append(_UntilNode(left, right, a, b))
            return ("until", len(self.untils) - 1, 1.0)
        raise STLUnsupportedError(f"unknown STL node {type(f).__name__}")

    def _window(self, child: _Expr, a: int, b: int, is_max: bool) -> _Expr:
        self.windows.append(_Window(child, a, b, is_max))
        return ("window", len(self.windows) - 1, 1.0)


def _negate(e: _Expr) -> _Expr:
    kind = e[0]
    if kind in ("pred", "window", "until"):
        return (kind, e[1], -e[2])
    if kind == "const":
        return ("const", -e[1])
    return ("max" if kind == "min" else "min", tuple(_negate(c) for c in e[1]))


def _evaluate(e: _Expr, rows: Mapping[str, torch.Tensor], like: torch.Tensor) -> torch.Tensor:
    kind = e[0]
    if kind == "const":
        return torch.full_like(like, e[1])
    if kind in ("pred", "window", "until"):
        value = rows[kind][e[1]]
        return value if e[2] > 0 else -value
    parts = [_evaluate(c, rows, like) for c in e[1]]
    out = parts[0]
    for p in parts[1:]:
        out = torch.minimum(out, p) if kind == "min" else torch.maximum(out, p)
    return out


def signed_distance(polygon: ConvexPolygon, x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    """Signed distance (m, + inside) of points (x, y) to a convex polygon: the formulas of
    :meth:`ConvexPolygon.signed_distance_xy` (closed form for an axis-aligned box)."""
    box = polygon._box
    if box is not None:
        dx = torch.maximum(box[0] - x, x - box[1])
        dy = torch.maximum(box[2] - y, y - box[3])
        inside = (dx <= 0.0) & (dy <= 0.0)
        outside = torch.sqrt(torch.clamp(dx, min=0.0) ** 2 + torch.clamp(dy, min=0.0) ** 2)
        return torch.where(inside, -torch.maximum(dx, dy), -outside)
    def line_and_segment(edge: Edge) -> tuple[torch.Tensor, torch.Tensor]:
        # the distance to the edge's supporting line (< 0 inside) and the squared distance to the edge segment
        vx, vy, ex, ey, nx, ny, off, ee = edge
        t = torch.clamp(((x - vx) * ex + (y - vy) * ey) / ee, 0.0, 1.0)
        dx, dy = x - vx - t * ex, y - vy - t * ey
        return nx * x + ny * y - off, dx * dx + dy * dy

    worst, best = line_and_segment(polygon._edges_py[0])
    for edge in polygon._edges_py[1:]:
        d, d2 = line_and_segment(edge)
        worst, best = torch.maximum(worst, d), torch.minimum(best, d2)
    return torch.where(worst <= 0.0, -worst, -torch.sqrt(best))


class BatchedMonitor:
    """Online robustness (m) of several formulas for N envs at once, each env at its own sample index.

    Args:
        formulas: the formulas (e.g. the task and its conjuncts); all share the predicate evaluations.
        regions: region name -> polygon (scenario regions and obstacles).
        dt: sampling period (s).
        body_names: names of the bodies in the order of the position tensors' body axis.
        num_envs, device, dtype: shape and placement of the state.

    :meth:`update` takes the positions of sample k of every env and returns [n_formulas, N] values equal to
    what one :class:`~impact_env.stl.OnlineMonitor` per env and formula returns after that sample.
    """

    def __init__(self, formulas: Sequence[Formula], regions: Mapping[str, ConvexPolygon], dt: float,
                 body_names: Sequence[str], num_envs: int, device: torch.device, dtype: torch.dtype) -> None:
        self.dt = check_dt(dt)
        for f in formulas:
            check_regions(f, regions)
        comp = _Compiler(regions, {name: i for i, name in enumerate(body_names)}, self.dt)
        self.roots = [comp.root(f) for f in formulas]
        self.horizons = [horizon_steps(f, self.dt) for f in formulas]
        self.preds = comp.preds
        self.polygons = [regions[name] for _, name in comp.preds]
        self.windows, self.untils = comp.windows, comp.untils
        opts = TensorKwargs(device=device, dtype=dtype)
        col = (len(self.windows), 1)
        self._a = torch.tensor([w.a for w in self.windows], device=device).reshape(col)
        self._b = torch.tensor([w.b for w in self.windows], device=device).reshape(col)
        self._is_max = torch.tensor([w.is_max for w in self.windows], device=device).reshape(col)
        self._init = torch.tensor([-_INF if w.is_max else _INF for w in self.windows], **opts).reshape(col)
        self.acc = self._init.expand(len(self.windows), num_envs).clone()
        self.run = torch.full((len(self.untils), num_envs), _INF, **opts)
        self.best = torch.full((len(self.untils), num_envs), -_INF, **opts)

    @property
    def state(self) -> MonitorState:
        """(window accumulators [W, N], until running minima [U, N], until bests [U, N])."""
        return self.acc, self.run, self.best

    @state.setter
    def state(self, value: MonitorState) -> None:
        self.acc, self.run, self.best = value

    def reset(self, mask: torch.Tensor | None = None) -> None:
        """Forget the samples of the envs in ``mask`` ([N] bool; all envs if None)."""
        self.state = self.reset_state(self.state, mask)

    def reset_state(self, state: MonitorState, mask: torch.Tensor | None) -> MonitorState:
        """``state`` with the envs of ``mask`` (all if None) back to "no sample yet"."""
        acc, run, best = state
        if mask is None:
            return self._init.expand_as(acc).clone(), torch.full_like(run, _INF), torch.full_like(best, -_INF)
        return torch.where(mask, self._init, acc), torch.where(mask, _INF, run), torch.where(mask, -_INF, best)

    def predicates(self, pos: torch.Tensor) -> torch.Tensor:
        """[n_predicates, N] signed distances of the predicates' bodies to their regions; pos is [2, B, N]."""
        out = [signed_distance(poly, pos[0, b], pos[1, b]) for (b, _), poly in zip(self.preds, self.polygons)]
        return torch.stack(out) if out else pos.new_zeros(0, pos.shape[-1])

    def update(self, pos: torch.Tensor, k: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
        """Take sample ``k`` ([N] int64, per env) at positions ``pos`` ([2, B, N], m); return [F, N] values.

        With ``mask`` ([N] bool), only those envs take the sample; the others keep their state (their
        returned values are then meaningless).
        """
        self.state, values = self.update_state(self.state, pos, k, mask)
        return values

    def update_state(self, state: MonitorState, pos: torch.Tensor, k: torch.Tensor,
                     mask: torch.Tensor | None = None) -> tuple[MonitorState, torch.Tensor]:
        """:meth:`update` as a pure function of the monitor state: returns (new state, values)."""
        acc, run, best = state
        d = self.predicates(pos)
        like = pos[0, 0]
        rows = {"pred": d}
        if self.windows:
            child = torch.stack([_evaluate(w.child, rows, like) for w in self.windows])
            upd = torch.where(self._is_max, torch.maximum(acc, child), torch.minimum(acc, child))
            started = k >= self._a
            live = started & (k <= self._b)
            if mask is not None:
                live = live & mask
            acc = torch.where(live, upd, acc)
            rows["window"] = torch.where(started, acc, child)
        if self.untils:
            values = []
            runs, bests = list(run.unbind(0)), list(best.unbind(0))
            for i, u in enumerate(self.untils):
                left, right = _evaluate(u.left, rows, like), _evaluate(u.right, rows, like)
                live = k <= u.b if mask is None else (k <= u.b) & mask
                runs[i] = torch.where(live, torch.minimum(runs[i], left), runs[i])
                m = torch.minimum(right, runs[i])
                take = live & (k >= u.a)
                bests[i] = torch.where(take, torch.maximum(bests[i], m), bests[i])
                values.append(torch.where(k >= u.a, bests[i], m))
            run, best = torch.stack(runs), torch.stack(bests)
            rows["until"] = torch.stack(values)
        return (acc, run, best), torch.stack([_evaluate(r, rows, like) for r in self.roots])
