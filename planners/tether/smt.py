"""The thesis's planner (Sec. 4.4) with an SMT solver that installs from the package index: z3.

The thesis hands its hybrid automaton to dReach / dReal, which cannot be installed today. With one active
anchor the flow of Eq. 5 is a straight line toward the anchor, so a pull from ``p`` toward ``a`` ends at a
point of that segment outside the stop radius: polynomial constraints, which z3 decides exactly over the
reals. :func:`plan_smt` is the thesis's divide and conquer over paths of the region graph (incomplete, like
the thesis's); :func:`bounded_search` is the whole automaton as one bounded model check, whose smallest
satisfiable number of pulls compares with the exact planner. Both enforce line of sight from the start of
each pull to its anchor; ``rule`` picks the anchors a region's modes may use (:mod:`~planners.tether.automaton`).
The encodings in detail: ``docs/planner_design.md#smt-planner``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from fractions import Fraction

import numpy as np
import shapely
from shapely.geometry import Point, Polygon

from impact_env.config_checks import check_choice, check_integer, check_number
from impact_env.tether.station import Station
from planners.errors import PlannerError, SmtNoPlanError
from planners.tether.automaton import RULES, ThesisMap, build_thesis_map, half_planes
from planners.tether.geometry import AREA_EPS_M2, clean, polygons_of, visibility_polygon
from planners.tether.plan import Pull, TetherPlan


def _z3():
    try:
        import z3
    except ImportError:  # pragma: no cover - make test installs it
        from planners.errors import SolverNotAvailableError

        raise SolverNotAvailableError("the thesis pipeline needs z3: pip install 'impact_env[tether]' "
                                      "(the z3-solver package)") from None
    return z3


@dataclass(frozen=True)
class SmtConfig:
    """Options of the z3 pipeline (the margins as the exact planner's, so that both solve the same problem)."""

    rule: str = "region"
    """The anchors a region's modes may use: ``"region"`` (the thesis's) or ``"line_of_sight"``."""
    max_pulls_per_region: int = 3
    """The sub-problems' bound on pulls (divide and conquer)."""
    max_paths: int = 8
    """Region-graph paths tried before giving up."""
    timeout_s: float = 60.0
    """z3's limit per check (s); a check that hits it counts as "no plan" and is reported."""
    clearance_m: float = 0.02
    """Extra distance (m) between the cargo disc and the walls, as the exact planner's."""
    stop_margin_m: float = 0.1
    """A pull ends at least this far (m) outside its anchor's stop radius, as the exact planner's."""
    target_margin_m: float = 0.05
    """Shrinks each sub-problem's transition zone (m), so that the next sub-problem starts inside its region
    rather than on its border."""
    goal_margin_m: float = 0.15
    """The last pull ends this far (m) inside the goal box, as the exact planner's."""

    def __post_init__(self) -> None:
        check_choice(self, "rule", PlannerError, RULES)
        for name in ("max_pulls_per_region", "max_paths"):
            check_integer(self, name, PlannerError, low=1)
        check_number(self, "timeout_s", PlannerError, low=0, low_open=True)
        for name in ("clearance_m", "stop_margin_m", "target_margin_m", "goal_margin_m"):
            check_number(self, name, PlannerError, low=0)


@dataclass
class SmtStats:
    checks: int = 0
    sat: int = 0
    unsat: int = 0
    unknown: int = 0
    solve_s: float = 0.0
    paths_tried: int = 0
    log: list[str] = field(default_factory=list)
    verdicts: list[str] = field(default_factory=list)  # of every check, in order
    failures: list[dict] = field(default_factory=list)  # per region path that gave no plan: where and why


def _val(model, v) -> float:
    z3 = _z3()
    e = model.eval(v, model_completion=True)
    if z3.is_rational_value(e):
        return float(Fraction(e.numerator_as_long(), e.denominator_as_long()))
    return float(Fraction(e.approx(30).as_fraction()))


def _in_rows(z3, x, y, rows, slack: float = 0.0):
    return z3.And([a * x + b * y <= c + slack for a, b, c in rows])


def _triangles(geom) -> list[list[tuple[float, float, float]]]:
    """Half-plane rows of the triangles of a polygonal set (shapely's constrained Delaunay triangulation)."""
    out = []
    for p in polygons_of(geom):
        for t in shapely.get_parts(shapely.constrained_delaunay_triangles(p)):
            if t.area > AREA_EPS_M2:
                out.append(half_planes(t))
    return out


class _Encoder:
    """Shared pieces of both encodings: anchors' visible triangles per region, the pull constraints."""

    def __init__(self, tmap: ThesisMap, config: SmtConfig) -> None:
        self.tmap, self.config = tmap, config
        self.st = tmap.station
        self.stop_m = self.st.stop_radius_m + config.stop_margin_m
        self._vis: dict[int, object] = {}
        self._tri: dict[tuple[int, int], list[list[tuple[float, float, float]]] | None] = {}
        self.stats = SmtStats()

    def visible_triangles(self, region: int, anchor: int) -> list[list[tuple[float, float, float]]] | None:
        """Triangles of the part of ``region`` that sees ``anchor``; None if the whole region sees it."""
        key = (region, anchor)
        if key not in self._tri:
            if anchor not in self._vis:
                self._vis[anchor] = visibility_polygon(self.st, anchor)
            poly = self.tmap.regions[region].polygon
            seen = clean(poly.intersection(self._vis[anchor]))
            self._tri[key] = None if poly.difference(seen).area <= AREA_EPS_M2 else _triangles(seen)
        return self._tri[key]

    def pull(self, z3, px, py, qx, qy, anchor: int):
        """A straight pull from (px, py) to (qx, qy) toward ``anchor``, ending outside the stop radius."""
        ax, ay = map(float, self.st.anchor_positions[anchor])
        dx, dy = qx - px, qy - py
        ux, uy = ax - px, ay - py
        return z3.And(dx * uy - dy * ux == 0, dx * ux + dy * uy >= 0, dx * ux + dy * uy <= ux * ux + uy * uy,
                      (qx - ax) * (qx - ax) + (qy - ay) * (qy - ay) >= self.stop_m ** 2)

    def sees(self, z3, x, y, region: int, anchor: int):
        tri = self.visible_triangles(region, anchor)
        if tri is None:
            return z3.BoolVal(True)
        if not tri:
            return z3.BoolVal(False)
        return z3.Or([_in_rows(z3, x, y, rows) for rows in tri])

    def check(self, solver, what: str) -> str:
        t0 = time.perf_counter()
        result = str(solver.check())
        dt = time.perf_counter() - t0
        result = result if result in ("sat", "unsat") else "unknown"  # unknown: z3 hit its time limit
        self.stats.checks += 1
        self.stats.solve_s += dt
        setattr(self.stats, result, getattr(self.stats, result) + 1)
        self.stats.log.append(f"{what}: {result} in {dt:.3f} s")
        self.stats.verdicts.append(result)
        return result


def goal_zone(station: Station, margin: float) -> Polygon:
    """The goal box shrunk by ``margin`` (the box itself if that leaves nothing), as the exact planner's."""
    x0, x1, y0, y1 = station.goal_box
    if x1 - x0 > 2 * margin and y1 - y0 > 2 * margin:
        return shapely.box(x0 + margin, y0 + margin, x1 - margin, y1 - margin)
    return shapely.box(x0, y0, x1, y1)


def _target(tmap: ThesisMap, path: list[int], i: int, config: SmtConfig) -> Polygon:
    region = tmap.regions[path[i]].polygon
    if i + 1 < len(path):
        zone = clean(tmap.overlap(path[i], path[i + 1]))
        margin = config.target_margin_m
    else:
        return clean(region.intersection(goal_zone(tmap.station, config.goal_margin_m)))
    zone = clean(zone)
    if zone.is_empty:
        return zone
    inner = clean(zone.buffer(-margin, join_style="mitre"))
    return inner if not inner.is_empty else zone


def _solve_region(enc: _Encoder, region: int, start: np.ndarray, target: Polygon, n: int):
    """Sub-problem of Sec. 4.4: ``n`` pulls inside ``region`` from ``start`` into ``target``; the pulls or None."""
    z3 = _z3()
    anchors = enc.tmap.region_anchors[region]
    rows = half_planes(enc.tmap.regions[region].polygon)
    trows = half_planes(target)
    s = z3.SolverFor("QF_NRA")
    s.set("timeout", int(1000 * enc.config.timeout_s))
    xs = [z3.RealVal(float(start[0]))] + [z3.Real(f"x{j}") for j in range(1, n + 1)]
    ys = [z3.RealVal(float(start[1]))] + [z3.Real(f"y{j}") for j in range(1, n + 1)]
    choice = [z3.Int(f"c{j}") for j in range(1, n + 1)]
    for j in range(1, n + 1):
        s.add(_in_rows(z3, xs[j], ys[j], rows))
        options = []
        for i, a in enumerate(anchors):
            options.append(z3.And(choice[j - 1] == i, enc.pull(z3, xs[j - 1], ys[j - 1], xs[j], ys[j], a),
                                  enc.sees(z3, xs[j - 1], ys[j - 1], region, a)))
        s.add(z3.Or(options) if options else z3.BoolVal(False))
    s.add(_in_rows(z3, xs[n], ys[n], trows))
    if enc.check(s, f"region {region}, {n} pulls") != "sat":
        return None
    m = s.model()
    pts = [np.asarray(start, float)] + [np.array([_val(m, xs[j]), _val(m, ys[j])]) for j in range(1, n + 1)]
    return [Pull(anchors[m.eval(choice[j - 1]).as_long()], tuple(pts[j - 1]), tuple(pts[j])) for j in range(1, n + 1)]


def plan_smt(station: Station, config: SmtConfig | None = None, tmap: ThesisMap | None = None) -> TetherPlan:
    """The thesis's divide and conquer along region-graph paths (see the module docstring).

    Raises:
        SmtNoPlanError: no path gave a plan within the bounds (with the checks' log in ``stats``).
    """
    import networkx as nx  # imported here, as in build_thesis_map

    config = config or SmtConfig()
    t0 = time.perf_counter()
    tmap = tmap or build_thesis_map(station, config.rule, config.clearance_m)
    enc = _Encoder(tmap, config)
    start = np.asarray(station.cargo.start_m, float)
    sources = tmap.regions_containing(start)
    goals = tmap.goal_regions()
    paths: list[list[int]] = []
    for s in sources:
        for g in goals:
            try:
                paths.extend(p for _, p in zip(range(config.max_paths), nx.shortest_simple_paths(tmap.graph, s, g)))
            except nx.NetworkXNoPath:
                continue
    paths = sorted(paths, key=len)[: config.max_paths]
    for path in paths:
        enc.stats.paths_tried += 1
        here, pulls, ok = start, [], True
        for i, region in enumerate(path):
            target = _target(tmap, path, i, config)
            if target.is_empty:
                ok = False
                enc.stats.failures.append({"path": list(path), "region": region, "why": "no transition zone",
                                           "verdicts": []})
                break
            if target.distance(Point(*here)) < 1e-12:
                continue  # already in the transition zone: zero pulls
            first = len(enc.stats.verdicts)
            for n in range(1, config.max_pulls_per_region + 1):
                got = _solve_region(enc, region, here, target, n)
                if got is not None:
                    pulls.extend(got)
                    here = np.asarray(got[-1].end_m)
                    break
            else:
                ok = False
                enc.stats.failures.append({"path": list(path), "region": region, "why": "no pulls",
                                           "verdicts": enc.stats.verdicts[first:]})
                enc.stats.log.append(f"path {path}: region {region} has no solution with up to "
                                     f"{config.max_pulls_per_region} pulls")
                break
        if ok:
            return TetherPlan(station=station.name, start_m=tuple(start), goal_box=station.goal_box, pulls=pulls,
                              pull_speed_mps=station.pull_speed_mps, switch_time_s=station.switch_time_s,
                              method=f"smt-divide-and-conquer ({config.rule} rule)",
                              solve_time_s=time.perf_counter() - t0,
                              stats={"path": path, "regions": len(tmap.regions), "checks": enc.stats.checks,
                                     "z3_s": enc.stats.solve_s, "unknown": enc.stats.unknown})
    raise SmtNoPlanError(no_plan_message(station, config, paths, enc.stats),
                         stats={"log": enc.stats.log, "checks": enc.stats.checks, "failures": enc.stats.failures,
                                "sat": enc.stats.sat, "unsat": enc.stats.unsat, "unknown": enc.stats.unknown})


def no_plan_message(station: Station, config: SmtConfig, paths: list[list[int]], stats: SmtStats) -> str:
    """Why the divide and conquer gave no plan: the rule, each region path and the region it stopped at with
    its z3 verdicts (pulls 1, 2, ...), and the verdicts' totals; ``unknown`` is z3 hitting its time limit."""
    if not paths:
        where = "the region graph has no path from the start's region to a goal region"
    else:
        parts = []
        for f in stats.failures:
            if f["why"] == "no transition zone":
                parts.append(f"path {f['path']} stops at region {f['region']}: no overlap with the next region")
            else:
                verdicts = ", ".join(f"{n} pull{'s' if n > 1 else ''} {v}" for n, v in enumerate(f["verdicts"], 1))
                parts.append(f"path {f['path']} stops at region {f['region']} ({verdicts})")
        where = "; ".join(parts)
    timeouts = (f"; unknown means z3 reached its {config.timeout_s:g} s limit, so a plan may exist: raise "
                "SmtConfig.timeout_s" if stats.unknown else "")
    return (f"station {station.name!r}: the thesis pipeline ({config.rule} rule) found no plan within its budget "
            f"({len(paths)} region path(s), up to {config.max_pulls_per_region} pulls per region): {where}. z3 "
            f"verdicts: {stats.sat} sat, {stats.unsat} unsat, {stats.unknown} unknown{timeouts}. Not a proof "
            "that no plan exists (the exact planner, --method reachability, decides that)")


@dataclass
class BoundedResult:
    """The outcome of :func:`bounded_search`: the fewest pulls found (or None), the plan, and per bound the
    answer (``"sat"``, ``"unsat"`` or ``"unknown"`` on a timeout)."""

    pulls: int | None
    plan: TetherPlan | None
    answers: dict[int, str]
    solve_s: float


def bounded_search(station: Station, max_pulls: int = 4, config: SmtConfig | None = None,
                   tmap: ThesisMap | None = None) -> BoundedResult:
    """The whole automaton as one bounded model check with ``n = 0 .. max_pulls`` single-anchor pulls."""
    z3 = _z3()
    config = config or SmtConfig(rule="line_of_sight")
    t0 = time.perf_counter()
    tmap = tmap or build_thesis_map(station, config.rule, config.clearance_m)
    enc = _Encoder(tmap, config)
    regions = [r.index for r in tmap.regions]
    m_split = len(regions)  # a straight pull crosses each convex region at most once
    goal = clean(goal_zone(station, config.goal_margin_m).intersection(
        shapely.union_all([r.polygon for r in tmap.regions])))
    goal_rows = half_planes(goal) if goal.geom_type == "Polygon" else []
    start = np.asarray(station.cargo.start_m, float)
    answers: dict[int, str] = {}
    if goal_rows and goal.distance(Point(*start)) < 1e-12:
        return BoundedResult(0, None, {0: "sat"}, time.perf_counter() - t0)
    answers[0] = "unsat"
    for n in range(1, max_pulls + 1):
        s = z3.SolverFor("QF_NRA")
        s.set("timeout", int(1000 * config.timeout_s))
        px = [z3.RealVal(float(start[0]))] + [z3.Real(f"x{j}") for j in range(1, n + 1)]
        py = [z3.RealVal(float(start[1]))] + [z3.Real(f"y{j}") for j in range(1, n + 1)]
        choice = [z3.Int(f"c{j}") for j in range(1, n + 1)]
        for j in range(1, n + 1):
            mus = [z3.RealVal(0)] + [z3.Real(f"mu{j}_{i}") for i in range(1, m_split)] + [z3.RealVal(1)]
            for i in range(1, m_split):
                s.add(mus[i - 1] <= mus[i], mus[i] <= 1)
            qx = [px[j - 1] + mus[i] * (px[j] - px[j - 1]) for i in range(m_split + 1)]
            qy = [py[j - 1] + mus[i] * (py[j] - py[j - 1]) for i in range(m_split + 1)]
            options = []
            for a in range(station.n_anchors):
                allowed = [r for r in regions if a in tmap.region_anchors[r]]
                if not allowed:
                    continue
                pieces = [z3.Or([z3.And(_in_rows(z3, qx[i], qy[i], half_planes(tmap.regions[r].polygon)),
                                        _in_rows(z3, qx[i + 1], qy[i + 1], half_planes(tmap.regions[r].polygon)))
                                 for r in allowed]) for i in range(m_split)]
                sight = z3.Or([z3.And(_in_rows(z3, px[j - 1], py[j - 1], half_planes(tmap.regions[r].polygon)),
                                      enc.sees(z3, px[j - 1], py[j - 1], r, a)) for r in allowed])
                options.append(z3.And(choice[j - 1] == a, enc.pull(z3, px[j - 1], py[j - 1], px[j], py[j], a),
                                      sight, *pieces))
            s.add(z3.Or(options) if options else z3.BoolVal(False))
        s.add(_in_rows(z3, px[n], py[n], goal_rows) if goal_rows else z3.BoolVal(False))
        answers[n] = enc.check(s, f"bounded search, {n} pulls")
        if answers[n] == "sat":
            m = s.model()
            pts = [start] + [np.array([_val(m, px[j]), _val(m, py[j])]) for j in range(1, n + 1)]
            pulls = [Pull(m.eval(choice[j - 1]).as_long(), tuple(pts[j - 1]), tuple(pts[j])) for j in range(1, n + 1)]
            plan = TetherPlan(station=station.name, start_m=tuple(start), goal_box=station.goal_box, pulls=pulls,
                              pull_speed_mps=station.pull_speed_mps, switch_time_s=station.switch_time_s,
                              method=f"smt-bounded ({config.rule} rule)", solve_time_s=time.perf_counter() - t0,
                              stats={"answers": answers, "z3_s": enc.stats.solve_s})
            return BoundedResult(n, plan, answers, time.perf_counter() - t0)
    return BoundedResult(None, None, answers, time.perf_counter() - t0)
