"""Compile an STL syntax tree (impact_env.stl) into mixed-integer constraints (paper Eq. 21-22).

The tree is first put in negation normal form. Robustness is encoded one-sidedly, which is exact at the
optimum because the planner maximises it: ``r <= min(...)`` is a set of plain rows, ``r <= max(...)`` picks
one child with binaries and big-M rows. Predicates are evaluated on a whole grid interval through the control
points of the body's curve there (convex hull property: sound, conservative), ``in(S, R)`` per face of R
(Eq. 21) and ``!in(S, R)`` by one face chosen with binaries (Eq. 22). A body's points may be a
:class:`PointProduct` (the impact-robust planner's copies and boxes), encoded exactly with one auxiliary per
axis. Temporal operators are evaluated at t = 0 over the grid intervals that meet their window, with time
gates known when the model is built; temporal operators nested inside temporal operators are rejected with
:class:`UnsupportedSpecError`. The encoding in full: ``docs/planner_design.md#stl-encoding``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from impact_env.geometry import ConvexPolygon
from impact_env.stl import Always, And, Eventually, FalseFormula, Formula, InRegion, Not, Or, TrueFormula, Until
from planners.errors import UnsupportedSpecError
from planners.offline.milp.model import LinExpr, Model
from planners.offline.milp.trajectories import Grid, Point


@dataclass(frozen=True)
class PointProduct:
    """The points (x, y) for every x in ``xs`` and every y in ``ys`` (LinExprs)."""

    xs: tuple[LinExpr, ...]
    ys: tuple[LinExpr, ...]


PointSet = Point | PointProduct


class NotInRegion(Formula):
    """The negated predicate !in(body, region), a leaf of the negation normal form."""

    def __init__(self, body: str, region: str) -> None:
        self.body, self.region = body, region

    @property
    def children(self) -> tuple[Formula, ...]:
        return ()

    def _text(self) -> str:
        return f"!in({self.body}, {self.region})"


def negation_normal_form(f: Formula, negate: bool = False) -> Formula:
    """Push negations down to the predicates (De Morgan, !F = G!, !G = F!)."""
    if isinstance(f, Not):
        return negation_normal_form(f.child, not negate)
    if isinstance(f, InRegion):
        return NotInRegion(f.body, f.region) if negate else f
    if isinstance(f, TrueFormula):
        return FalseFormula() if negate else f
    if isinstance(f, FalseFormula):
        return TrueFormula() if negate else f
    if isinstance(f, (And, Or)):
        kids = tuple(negation_normal_form(c, negate) for c in f.children)
        return (Or if isinstance(f, And) == negate else And)(kids)
    if isinstance(f, (Eventually, Always)):
        kind = type(f) if not negate else (Always if isinstance(f, Eventually) else Eventually)
        return kind(f.a_s, f.b_s, negation_normal_form(f.child, negate))
    if isinstance(f, Until):
        if negate:
            raise UnsupportedSpecError(f"the planner cannot encode a negated until: !({f})")
        return Until(f.a_s, f.b_s, negation_normal_form(f.left), negation_normal_form(f.right))
    raise UnsupportedSpecError(f"unknown STL node {type(f).__name__}")


class STLEncoder:
    """Adds the robustness encoding of formulas to a model.

    Args:
        model: the model to extend.
        grid: the planner's time grid.
        points: ``points(body, k)`` gives the control points of the body on interval k: LinExpr pairs or
            :class:`PointProduct` sets, every point of which must satisfy a predicate.
        boxes: per body, the box its centre stays in (for big-Ms and to skip impossible faces).
        regions: name -> convex polygon.
        bound_propagation: bound every robustness variable by what its predicates can reach (else only by
            the scene's diagonal; kept to measure the difference).
        reuse_clearance: a predicate ``!in(body, region)`` on an interval where :meth:`clearance` already keeps
            every point of the body at least m beyond a face of the region has robustness >= m: use m, a
            constant, instead of encoding the faces again. Only for a planner that requires the task's
            robustness >= 0 and does not maximise it (the impact-robust one): the value is a lower bound.
        lp_optimum: the optimal objective of a small LP, or None where it is not proven
            (:func:`planners.offline.solvers.lp_optimum`): the bound of an ``in`` predicate is the Chebyshev
            radius of its region within the body's box. Given by the planner, so that this model-building
            layer needs no solver (the solvers take its models).
    """

    def __init__(self, model: Model, grid: Grid, points: Callable[[str, int], Sequence[PointSet]],
                 boxes: dict[str, tuple[float, float, float, float]], regions: dict[str, ConvexPolygon],
                 bound_propagation: bool = True, reuse_clearance: bool = False, *,
                 lp_optimum: Callable[[Model], float | None]) -> None:
        self.model, self.grid, self.points, self.boxes, self.regions = model, grid, points, boxes, regions
        self.lp_optimum = lp_optimum
        self.bound_propagation = bound_propagation
        self.reuse_clearance = reuse_clearance
        self._clearance: dict[tuple[str, str, int], float] = {}
        corners = [(b[0], b[2]) for b in boxes.values()] + [(b[1], b[3]) for b in boxes.values()]
        corners += [tuple(v) for poly in regions.values() for v in poly.vertices]
        xs, ys = [c[0] for c in corners], [c[1] for c in corners]
        # no signed distance between points of this scene exceeds its diagonal: the bound of every r
        self.bound = math.hypot(max(xs) - min(xs), max(ys) - min(ys))
        self.big_m = 2.0 * self.bound
        # Both caches are keyed by id() and hold the keyed object in their value: an id is unique only while
        # its object lives, and the negation normal form of each conjunct is a new tree that the caller drops
        # once it is encoded. Keyed by the ids of dead nodes, a later conjunct's node allocated at a freed
        # address was given an earlier conjunct's encoding (two_objects: R2's pillar constraint became R1's),
        # depending on the heap, i.e. on what the process had done before
        # (tests/planners/offline/milp/test_stl_encoding.py).
        self._memo: dict[tuple[int, int], tuple[Formula, LinExpr]] = {}  # (id(node), k) -> (node, robustness)
        self._ub: dict[int, tuple[LinExpr, float]] = {}  # id(r) -> (r, an upper bound of its value)
        self._pred_ub: dict[tuple[str, str, bool], float] = {}
        self._faces: dict[tuple[str, str, int], list[tuple[int, LinExpr | None]]] = {}
        self.group = "task encoding"

    def _var(self, name: str, ub: float | None = None) -> LinExpr:
        """A robustness variable with the tightest upper bound known: it is what makes the LP relaxation
        prove the geometric optimum at once instead of after a long branch and bound."""
        ub = self.bound if ub is None or not self.bound_propagation else min(ub, self.bound)
        r = self.model.add_var(-self.bound, ub, name=name)
        self._ub[id(r)] = (r, ub)
        return r

    def upper_bound(self, r: LinExpr) -> float:
        if not r.terms:
            return r.const
        known = self._ub.get(id(r))
        return known[1] if known is not None else self.bound

    def predicate_upper_bound(self, body: str, region: str, inside: bool) -> float:
        """Largest robustness the predicate can have for this body anywhere in its allowed box.

        Inside: the Chebyshev radius of the region intersected with the box's reach (a 3-variable LP).
        Outside: the largest distance beyond any face over the box's corners.
        """
        key = (body, region, inside)
        if key not in self._pred_ub:
            poly = self.regions[region]
            x0, x1, y0, y1 = self.boxes[body]
            if inside:
                lp = Model(name="chebyshev")
                cx, cy, r = lp.add_var(x0, x1), lp.add_var(y0, y1), lp.add_var(-self.bound, self.bound)
                for n, b in zip(poly.normals, poly.offsets):
                    lp.add(cx * float(n[0]) + cy * float(n[1]) + r <= float(b), group="faces")
                lp.set_objective(r, maximize=True)
                optimum = self.lp_optimum(lp)
                ub = optimum + 1e-9 if optimum is not None else self.bound
            else:
                corners = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
                ub = float(np.max(corners @ poly.normals.T - poly.offsets)) + 1e-9
            self._pred_ub[key] = ub
        return self._pred_ub[key]

    # ------------------------------------------------------------------------------------- at t = 0
    def encode(self, formula: Formula) -> LinExpr:
        """Robustness (m) of the formula at t = 0, as a variable bounded above by the encoding."""
        return self._at0(negation_normal_form(formula))

    def _at0(self, f: Formula) -> LinExpr:
        if isinstance(f, (And, Or)):
            return self._combine(f, [self._at0(c) for c in f.children], "t0")
        if isinstance(f, Eventually):
            ks = self._window(f.a_s, f.b_s)
            return self._pick_max([self._on_interval(f.child, k) for k in ks], "F")
        if isinstance(f, Always):
            children = [self._on_interval(f.child, k) for k in self._window(f.a_s, f.b_s)]
            r = self._var("G", min(self.upper_bound(c) for c in children))
            for c in children:
                self.model.add(r <= c, group=self.group)
            return r
        if isinstance(f, Until):
            ks = self._window(f.a_s, f.b_s)
            candidates = []
            for k in ks:
                parts = [self._on_interval(f.right, k)] + [self._on_interval(f.left, j) for j in range(k + 1)]
                r_k = self._var(f"U@{k}", min(self.upper_bound(c) for c in parts))
                for c in parts:
                    self.model.add(r_k <= c, group=self.group)
                candidates.append(r_k)
            return self._pick_max(candidates, "U")
        # an atemporal formula at t = 0: the state at time 0 is the first control point of interval 0
        return self._on_interval(f, 0, first_point_only=True)

    def _window(self, a_s: float, b_s: float) -> list[int]:
        """Grid intervals that meet [a_s, b_s] (closed)."""
        eps = 1e-9 * self.grid.tf_s
        ks = [k for k in range(self.grid.intervals)
              if self.grid.knot(k) <= b_s + eps and self.grid.knot(k + 1) >= a_s - eps]
        if not ks:
            raise UnsupportedSpecError(f"interval [{a_s}, {b_s}] s lies outside the plan's horizon "
                                       f"[0, {self.grid.tf_s}] s")
        return ks

    # ------------------------------------------------------------------------------ on an interval k
    def _on_interval(self, f: Formula, k: int, first_point_only: bool = False) -> LinExpr:
        key = (id(f), k if not first_point_only else -1)
        if key in self._memo:
            return self._memo[key][1]
        if isinstance(f, (Eventually, Always, Until)):
            raise UnsupportedSpecError(f"the planner encodes temporal operators at the top of the task only; "
                                       f"{f} is nested inside another temporal operator")
        if isinstance(f, (And, Or)):
            r = self._combine(f, [self._on_interval(c, k, first_point_only) for c in f.children], f"@{k}")
        elif isinstance(f, TrueFormula):
            r = LinExpr.of(self.bound)
        elif isinstance(f, FalseFormula):
            r = LinExpr.of(-self.bound)
        elif isinstance(f, InRegion):
            r = self._inside(f.body, f.region, k, first_point_only)
        elif isinstance(f, NotInRegion):
            r = self._outside(f.body, f.region, k, first_point_only)
        else:  # pragma: no cover - negation_normal_form leaves nothing else
            raise UnsupportedSpecError(f"cannot encode {f}")
        self._memo[key] = (f, r)
        return r

    def _pts(self, body: str, k: int, first_point_only: bool) -> Sequence[PointSet]:
        pts = self.points(body, k)
        return pts[:1] if first_point_only else pts

    def _inside(self, body: str, region: str, k: int, first_point_only: bool) -> LinExpr:
        poly = self.regions[region]
        r = self._var(f"in({body},{region})@{k}", self.predicate_upper_bound(body, region, inside=True))
        for p in self._pts(body, k, first_point_only):
            for n, b in zip(poly.normals, poly.offsets):
                for dot in self._dots(body, p, n, upper=True, group=self.group):
                    self.model.add(r <= b - dot, group=self.group)
        return r

    def _dots(self, body: str, p: PointSet, n: np.ndarray, upper: bool, group: str) -> list[LinExpr]:
        """Expressions that bound n . q for every point q of ``p``: from above (``upper``) or below.

        A pair gives its own n . p. A product gives one expression per x (or y) when the face is parallel to
        an axis, else the sum of two auxiliaries u_x >= n_x x for every x and u_y >= n_y y for every y (<=
        for a lower bound): exact, since the extreme of a sum of independent terms is the sum of extremes.
        """
        nx, ny = float(n[0]), float(n[1])
        if not isinstance(p, PointProduct):
            return [p[0] * nx + p[1] * ny]
        if ny == 0.0:
            return [x * nx for x in p.xs]
        if nx == 0.0:
            return [y * ny for y in p.ys]
        x0, x1, y0, y1 = self.boxes[body]
        total = LinExpr()
        for coef, values, (lo, hi) in ((nx, p.xs, (x0, x1)), (ny, p.ys, (y0, y1))):
            ends = (coef * lo, coef * hi)
            aux = self.model.add_var(min(ends), max(ends), name=f"dot[{body}]")
            for v in values:
                self.model.add(aux >= v * coef if upper else aux <= v * coef, group=group)
            total = total + aux
        return [total]

    def _outside(self, body: str, region: str, k: int, first_point_only: bool) -> LinExpr:
        """r <= distance outside one face of the region, for every control point (Eq. 22)."""
        if self.reuse_clearance and not first_point_only and (body, region, k) in self._clearance:
            return LinExpr.of(self._clearance[(body, region, k)])
        r = self._var(f"!in({body},{region})@{k}", self.predicate_upper_bound(body, region, inside=False))
        self._beyond_one_face(body, region, k if not first_point_only else -1,
                              self._pts(body, max(k, 0), first_point_only), r, self.group)
        return r

    def _beyond_one_face(self, body: str, region: str, key_k: int, points: Sequence[PointSet],
                         lower: LinExpr | float, group: str) -> None:
        """Every point at least ``lower`` beyond the same face of the region, the face picked by binaries."""
        for face, w in self.face_choice(body, region, key_k, group):
            n, b = self.regions[region].normals[face], self.regions[region].offsets[face]
            slack = (1 - w) * self.big_m if w is not None else 0.0
            for p in points:
                for dot in self._dots(body, p, n, upper=False, group=group):
                    self.model.add(dot - float(b) + slack >= lower, group=group)

    def face_choice(self, body: str, region: str, k: int, group: str) -> list[tuple[int, LinExpr | None]]:
        """The faces the body may be beyond on interval k, each with its binary (None if it is the only one).

        A face whose outer half-space does not meet the body's allowed box can never be used and gets no
        binary; the binaries are shared by every constraint on (body, region, k), e.g. the task and the
        obstacle clearance; their "one face" row joins the group of the constraint that first asked.
        """
        key = (body, region, k)
        if key not in self._faces:
            poly = self.regions[region]
            x0, x1, y0, y1 = self.boxes[body]
            corners = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
            useful = [f for f in range(len(poly.offsets))
                      if np.max(corners @ poly.normals[f] - poly.offsets[f]) > 0.0]
            if not useful:
                useful = list(range(len(poly.offsets)))
            choice: list[tuple[int, LinExpr | None]]
            if len(useful) == 1:
                choice = [(useful[0], None)]
            else:
                ws = [self.model.add_binary(name=f"face[{body},{region},{k},{f}]") for f in useful]
                self.model.add(sum(ws, LinExpr()) == 1, group=group)
                choice = list(zip(useful, ws))
            self._faces[key] = choice
        return self._faces[key]

    def clearance(self, body: str, region: str, k: int, margin_m: float, group: str) -> None:
        """Keep the body's whole interval k at least ``margin_m`` outside the region (solid obstacles)."""
        self._beyond_one_face(body, region, k, self.points(body, k), margin_m, group)
        self._clearance[(body, region, k)] = max(margin_m, self._clearance.get((body, region, k), -math.inf))

    # ------------------------------------------------------------------------------- min / max
    def _combine(self, f: Formula, rs: list[LinExpr], tag: str) -> LinExpr:
        if isinstance(f, And):
            r = self._var(f"and{tag}", min(self.upper_bound(c) for c in rs))
            for c in rs:
                self.model.add(r <= c, group=self.group)
            return r
        return self._pick_max(rs, f"or{tag}")

    def _pick_max(self, rs: list[LinExpr], name: str) -> LinExpr:
        if len(rs) == 1:
            return rs[0]
        ub = max(self.upper_bound(c) for c in rs)
        r = self._var(name, ub)
        bs = [self.model.add_binary(name=f"pick[{name}]") for _ in rs]
        self.model.add(sum(bs, LinExpr()) >= 1, group=self.group)
        for c, b in zip(rs, bs):
            # r <= ub always; the row must not bind when b = 0, and c >= -bound: M = ub + bound
            self.model.add(r <= c + (1 - b) * (ub + self.bound), group=self.group)
        return r
