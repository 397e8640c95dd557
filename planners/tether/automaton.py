"""The region graph and the hybrid automaton of the thesis (Sec. 4.3, Eq. 1, 5-7).

The map is the cargo centre's free space (:func:`~planners.tether.geometry.free_space_polygon`), decomposed by
MP3 and extended (:mod:`~planners.tether.decomposition`, :mod:`~planners.tether.extension`):

- the **region graph** (networkx): a node per extended region, an edge between regions whose pieces share a
  border, carrying their overlap (the jump zone);
- the **hybrid automaton** (Eq. 1): a mode per region and set of at most ``k`` of its anchors, the region as
  invariant (Eq. 6), Eq. 5 as flow, jumps within a region and into a neighbour through the overlap (Eq. 7),
  and an initial and a final mode.

``rule`` picks the anchors a mode may use: the thesis's ``"region"`` (on a wall that bounds the region) or
``"line_of_sight"`` (any anchor some point of the region sees); the thesis's rule makes some feasible maps
infeasible. The automaton in full: ``docs/planner_design.md#region-graph-and-hybrid-automaton``.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import shapely
from shapely.geometry import Point, Polygon
from shapely.geometry.base import BaseGeometry

from impact_env.tether.station import Station
from planners.errors import PlannerError
from planners.tether.decomposition import mp3_decompose
from planners.tether.extension import ExtendedRegion, extend_regions
from planners.tether.geometry import AREA_EPS_M2, clean, free_space_polygon, polygons_of, visibility_polygon

if TYPE_CHECKING:  # networkx is imported when a map is built (it costs a tenth of a second at import)
    import networkx as nx

RULES = ("region", "line_of_sight")
HalfPlane = tuple[float, float, float]  # (a, b, c): a x + b y <= c


def half_planes(poly: Polygon) -> list[HalfPlane]:
    """The convex polygon as ``a x + b y <= c`` rows with unit normals (one per edge)."""
    c = np.asarray(shapely.orient_polygons(poly).exterior.coords)
    rows = []
    for u, v in zip(c[:-1], c[1:]):
        d = v - u
        n = float(np.hypot(*d))
        if n < 1e-12:
            continue
        a, b = d[1] / n, -d[0] / n  # outward normal of a CCW edge
        rows.append((float(a), float(b), float(a * u[0] + b * u[1])))
    return rows


@dataclass
class ThesisMap:
    """The decomposed and extended free space of a station, the region graph and the anchors of each region."""

    station: Station
    free: Polygon
    regions: list[ExtendedRegion]
    graph: nx.Graph
    rule: str
    region_anchors: dict[int, list[int]]
    clearance_m: float

    def regions_containing(self, point: tuple[float, float] | np.ndarray, tol: float = 1e-9) -> list[int]:
        pt = Point(float(point[0]), float(point[1]))
        return [r.index for r in self.regions if r.polygon.distance(pt) <= tol]

    def goal_regions(self) -> list[int]:
        box = shapely.box(self.station.goal_box[0], self.station.goal_box[2], self.station.goal_box[1],
                          self.station.goal_box[3])
        return [r.index for r in self.regions if r.polygon.intersection(box).area > AREA_EPS_M2]

    def overlap(self, i: int, j: int) -> BaseGeometry:
        return self.graph.edges[i, j]["overlap"]


def build_thesis_map(station: Station, rule: str = "region", clearance_m: float = 0.02) -> ThesisMap:
    """Decompose (MP3) and extend the free space and find each region's anchors under ``rule``."""
    import networkx as nx

    if rule not in RULES:
        raise PlannerError(f"rule must be one of {RULES}, got {rule!r}")
    free_all = polygons_of(free_space_polygon(station, clearance_m))
    if not free_all:
        raise PlannerError(f"station {station.name!r}: no free space for a cargo of radius {station.cargo.radius_m} m")
    start = Point(*station.cargo.start_m)
    free = min(free_all, key=lambda p: p.distance(start))  # the component the cargo is in
    pieces = mp3_decompose(list(shapely.simplify(free, 0.0).exterior.coords)[:-1])
    regions = extend_regions(pieces)
    graph = nx.Graph()
    for r in regions:
        graph.add_node(r.index, polygon=r.polygon, piece=r.piece)
    for r in regions:
        for j in r.neighbours:
            if j > r.index:
                graph.add_edge(r.index, j, overlap=clean(r.polygon.intersection(regions[j].polygon))
                               if r.polygon.intersection(regions[j].polygon).area > AREA_EPS_M2
                               else r.polygon.intersection(regions[j].polygon))
    rho = station.cargo.radius_m + clearance_m
    region_anchors: dict[int, list[int]] = {}
    vis = {a: visibility_polygon(station, a) for a in range(station.n_anchors)} if rule == "line_of_sight" else {}
    for r in regions:
        if rule == "region":
            pts = shapely.points(station.anchor_positions)
            near = shapely.distance(pts, r.polygon) <= rho + 1e-6
            region_anchors[r.index] = [int(a) for a in np.flatnonzero(near)]
        else:
            region_anchors[r.index] = [a for a in range(station.n_anchors)
                                       if r.polygon.intersection(vis[a]).area > AREA_EPS_M2]
    return ThesisMap(station, free, regions, graph, rule, region_anchors, clearance_m)


@dataclass(frozen=True)
class Mode:
    """A control mode: ``region`` (None for the initial and final modes), its ``anchors``, invariant rows."""

    name: str
    region: int | None
    anchors: tuple[int, ...]
    invariant: tuple[HalfPlane, ...]


@dataclass(frozen=True)
class Jump:
    """A control switch from mode ``source`` to ``target`` (names) with guard rows (empty: always enabled);
    the reset is the identity on (x, y)."""

    source: str
    target: str
    guard: tuple[HalfPlane, ...]


@dataclass
class HybridAutomaton:
    """Eq. 1 for one station: modes, jumps, the initial and the final mode, and the flows' constants.

    The jumps are many (every ordered pair of modes of a region, and of neighbouring regions: millions on the
    shipped maps with ``k = 2`` and the line-of-sight rule), so they are generated by :meth:`jumps`, not stored.
    """

    station: str
    modes: list[Mode]
    jump_groups: list[tuple[list[str], list[str], tuple[HalfPlane, ...]]]  # every source x every target, guard
    initial: str
    final: str
    start_m: tuple[float, float]
    goal_box: tuple[float, float, float, float]
    anchor_positions: np.ndarray
    pull_speed_mps: float
    k: int
    stats: dict = field(default_factory=dict)

    def mode(self, name: str) -> Mode:
        return next(m for m in self.modes if m.name == name)

    def jumps(self):
        """Every control switch (a generator of :class:`Jump`)."""
        for sources, targets, guard in self.jump_groups:
            for s in sources:
                for t in targets:
                    if s != t:
                        yield Jump(s, t, guard)

    @property
    def n_jumps(self) -> int:
        n = 0
        for sources, targets, _ in self.jump_groups:
            n += len(sources) * len(targets) - len(set(sources) & set(targets))
        return n


def build_automaton(tmap: ThesisMap, k: int | None = None) -> HybridAutomaton:
    """The thesis's automaton (Sec. 4.3) on a decomposed map, with modes of 1..k anchors per region."""
    st = tmap.station
    k = st.k if k is None else k
    if k < 1:
        raise PlannerError(f"k must be >= 1, got {k}")
    x0, x1, y0, y1 = st.goal_box
    goal_rows = ((-1.0, 0.0, -x0), (1.0, 0.0, x1), (0.0, -1.0, -y0), (0.0, 1.0, y1))
    sx, sy = st.cargo.start_m
    start_rows = ((-1.0, 0.0, -sx), (1.0, 0.0, sx), (0.0, -1.0, -sy), (0.0, 1.0, sy))
    modes = [Mode("init", None, (), start_rows), Mode("final", None, (), goal_rows)]
    by_region: dict[int, list[Mode]] = {}
    for r in tmap.regions:
        inv = tuple(half_planes(r.polygon))
        anchors = tmap.region_anchors[r.index]
        by_region[r.index] = [Mode(f"r{r.index}_a{'_'.join(map(str, combo))}", r.index, combo, inv)
                              for size in range(1, k + 1) for combo in itertools.combinations(anchors, size)]
        modes.extend(by_region[r.index])
    names = {r: [m.name for m in ms] for r, ms in by_region.items()}
    groups: list[tuple[list[str], list[str], tuple[HalfPlane, ...]]] = [(ns, ns, ()) for ns in names.values()]
    for i, j in tmap.graph.edges:
        ov = tmap.overlap(i, j)
        guard = tuple(half_planes(ov)) if ov.geom_type == "Polygon" and ov.area > AREA_EPS_M2 else \
            tuple(half_planes(shapely.convex_hull(ov).buffer(0)) if ov.area > 0 else ())
        if not guard:  # a zero-area overlap: the two regions' invariants meet on the shared border
            guard = tuple(half_planes(tmap.regions[i].polygon)) + tuple(half_planes(tmap.regions[j].polygon))
        groups.append((names[i], names[j], guard))
        groups.append((names[j], names[i], guard))
    for index in tmap.regions_containing(st.cargo.start_m):
        groups.append((["init"], names[index], ()))
    for index in tmap.goal_regions():
        groups.append((names[index], ["final"], goal_rows))
    ha = HybridAutomaton(station=st.name, modes=modes, jump_groups=groups, initial="init", final="final",
                         start_m=(sx, sy), goal_box=st.goal_box, anchor_positions=st.anchor_positions.copy(),
                         pull_speed_mps=st.pull_speed_mps, k=k,
                         stats={"regions": len(tmap.regions), "modes": len(modes), "rule": tmap.rule})
    ha.stats["jumps"] = ha.n_jumps
    return ha
