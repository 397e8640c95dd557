"""The exact planner: backward reachability over the anchors' visibility polygons, fewest pulls first.

With one active anchor the cargo moves in a straight line toward it at ``w``; more robots on other anchors add
speed but never reach a point that single pulls cannot, so reachability is decided over single pulls:
``R_0`` is the goal box in the free space and ``R_{n+1} = R_n U (union over anchors a of Pre_a(R_n))``,
computed exactly per radial cell (:mod:`~planners.tether.geometry`). The start in ``R_n`` and not in
``R_{n-1}``: ``n`` pulls is the fewest, and a plan is read forward level by level. ``R_{n+1} = R_n`` without
the start is the proof that no plan exists (:class:`TetherInfeasibleError` carries it). The levels do not
depend on the start, so a :class:`ReachabilityPlanner` replans from another point with a forward read only.
Why single pulls suffice, and how exact it is: ``docs/planner_design.md#exact-tether-planner``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import shapely
import shapely.ops
from shapely.geometry import Point
from shapely.geometry.base import BaseGeometry

from impact_env.config_checks import check_integer, check_number
from impact_env.tether.station import Station
from planners.errors import PlannerError
from planners.tether.braking import with_hold
from planners.tether.errors import TetherInfeasibleError
from planners.tether.geometry import (
    AREA_EPS_M2,
    RadialCells,
    clean,
    far_distance,
    free_space_polygon,
    pull_segment,
    radial_cells,
    seen_free_space,
    shadow_pieces,
)
from planners.tether.plan import Pull, TetherPlan

COVER_TOL_M = 1e-6  # a point this close to a level is in it (the rays between radial cells have no area)


@dataclass(frozen=True)
class ReachabilityConfig:
    """Options of the exact planner."""

    clearance_m: float = 0.02
    """Extra distance (m) kept between the cargo disc and the walls, on top of its radius."""
    stop_margin_m: float = 0.1
    """A pull ends at least this far (m) outside its anchor's stop radius, so that the environment does not
    release the tether before the planned switch point."""
    goal_margin_m: float = 0.15
    """The last pull must end this far (m) inside the goal box (if the box allows it)."""
    max_pulls: int = 40
    """Give up (with a PlannerError, not a proof) if the reachable set still grows after this many pulls."""
    depth_cap_m: float = 0.5
    """A switch point is chosen as deep as this (m) inside the next level's set, then by shortest path."""

    def __post_init__(self) -> None:
        for name in ("clearance_m", "stop_margin_m", "goal_margin_m", "depth_cap_m"):
            check_number(self, name, PlannerError, low=0)
        check_integer(self, "max_pulls", PlannerError, low=1)


class ReachabilityPlanner:
    """Backward reachability for one station; levels are computed on demand and kept (warm replanning).

    Args:
        station: the station (its polygon, anchors, cargo radius, stop radius, goal box, ``w``).
        config: see :class:`ReachabilityConfig`.
        anchors: the anchor indices the planner may use (default all), e.g. to model missing anchors.
    """

    def __init__(self, station: Station, config: ReachabilityConfig | None = None,
                 anchors: list[int] | None = None, _parent: ReachabilityPlanner | None = None) -> None:
        self.station = station
        self.config = config or ReachabilityConfig()
        t0 = time.perf_counter()
        self.stop_m = station.stop_radius_m + self.config.stop_margin_m
        self.anchor_ids = list(range(station.n_anchors)) if anchors is None else sorted(set(anchors))
        self._far = far_distance(station)
        self.free: BaseGeometry
        self.seen: dict[int, BaseGeometry]
        self.cells: dict[int, RadialCells]
        if _parent is not None:  # the anchors' visibility and radial cells do not depend on the other anchors
            self.free = _parent.free
            self.seen = {a: _parent.seen[a] for a in self.anchor_ids}
            self.cells = {a: c for a, c in _parent.cells.items() if a in self.seen}
        else:
            self.free = clean(free_space_polygon(station, self.config.clearance_m))
            # the free space each anchor sees; its radial cells are cut the first time a level's frontier is in sight
            self.seen = {a: seen_free_space(station, a, self.free) for a in self.anchor_ids}
            self.cells = {}
        self.usable = [a for a in self.anchor_ids if not self.seen[a].is_empty]
        if _parent is None:
            for a in self.usable:
                shapely.prepare(self.seen[a])
        x0, x1, y0, y1 = station.goal_box
        m = self.config.goal_margin_m
        inner = shapely.box(x0 + m, y0 + m, x1 - m, y1 - m) if x1 - x0 > 2 * m and y1 - y0 > 2 * m else None
        goal = clean(self.free.intersection(shapely.box(x0, y0, x1, y1)))
        if inner is not None and not clean(self.free.intersection(inner)).is_empty:
            goal = clean(self.free.intersection(inner))
        self.levels: list[BaseGeometry] = [goal]
        self.fixed_point = goal.is_empty
        self.setup_s = time.perf_counter() - t0
        self.level_s = 0.0

    def without(self, anchors: set[int] | list[int]) -> ReachabilityPlanner:
        """A planner for the same station without ``anchors`` (failed ones): it shares this one's free space,
        visibility polygons and radial cells (each anchor's own), so only the levels are computed again."""
        gone = set(anchors)
        return ReachabilityPlanner(self.station, self.config, [a for a in self.anchor_ids if a not in gone],
                                   _parent=self)

    # ----------------------------------------------------------------------------------- levels
    def pre(self, anchor: int, target: BaseGeometry) -> BaseGeometry:
        """``Pre_a(target)``: the points from which one pull toward ``anchor`` lands in ``target`` (those of
        ``target`` it sees, outside the stop disc, and what lies behind them)."""
        rc = self._cells(anchor) if anchor in self.seen and not self.seen[anchor].is_empty else None
        if rc is None or not len(rc.cells):
            return shapely.Polygon()
        landing = clean(target.intersection(rc.region).difference(rc.disc))
        return clean(shapely.union_all([landing, *self._pre_pieces(anchor, target)]))

    def _cells(self, anchor: int) -> RadialCells:
        if anchor not in self.cells:
            self.cells[anchor] = radial_cells(self.station, anchor, self.free, self.stop_m, region=self.seen[anchor])
        return self.cells[anchor]

    def _pre_pieces(self, anchor: int, target: BaseGeometry) -> list:
        """Polygons whose union with ``target`` is ``target U Pre_a(target)`` (the caller unions, once per level)."""
        if anchor not in self.seen or self.seen[anchor].is_empty or target.is_empty \
                or not self.seen[anchor].intersects(target):
            return []
        rc = self._cells(anchor)
        shapely.prepare(target)
        hit = np.flatnonzero(shapely.intersects(rc.cells, target))
        if not len(hit):
            return []
        seeds = shapely.intersection(rc.cells[hit], target)
        near = rc.near[hit]
        if near.any():  # a pull ends outside the stop radius
            seeds[near] = shapely.difference(seeds[near], rc.disc)
        # the seeds are in the target already; only what lies behind them is new
        owners_cells, seeds_kept = [], []
        for cell, seed, near_disc in zip(rc.cells[hit], seeds, near):
            seed = clean(seed)
            if seed.is_empty or (not near_disc and seed.area >= cell.area - AREA_EPS_M2):
                continue  # nothing, or the whole cell: nothing behind the seed inside the cell
            seeds_kept.append(seed)
            owners_cells.append(cell)
        if not seeds_kept:
            return []
        shadows, owner = shadow_pieces(rc.position_m, seeds_kept, self._far)
        if not len(shadows):
            return []
        # the shadow of a cell's seed, kept inside that cell: farther cells on the same rays are other intervals
        inside = shapely.intersection(shadows, np.asarray(owners_cells, dtype=object)[owner])
        return list(inside)

    def _grow(self) -> bool:
        """Add one level; returns False (and marks the fixed point) when it adds no area.

        ``Pre_a`` distributes over unions and ``Pre_a(R_{n-1})`` is already in ``R_n``, so only the frontier
        ``R_n \\ R_{n-1}`` is pulled back.
        """
        t0 = time.perf_counter()
        last = self.levels[-1]
        frontier = last if len(self.levels) == 1 else clean(last.difference(self.levels[-2]))
        parts = [last] + [p for a in self.usable for p in self._pre_pieces(a, frontier)]
        nxt = clean(shapely.union_all(parts))
        added = nxt.difference(last).area
        self.level_s += time.perf_counter() - t0
        if added <= AREA_EPS_M2:
            self.fixed_point = True
            return False
        self.levels.append(nxt)
        return True

    def level_of(self, point: np.ndarray | tuple[float, float]) -> int | None:
        """The fewest pulls from ``point`` to the goal (0 inside it), growing levels as needed; None when the
        reachable set reached its fixed point without the point (no plan exists)."""
        pt = Point(float(point[0]), float(point[1]))
        n = 0
        while True:
            if n >= len(self.levels):
                if self.fixed_point or len(self.levels) > self.config.max_pulls:
                    break
                if not self._grow():
                    break
                continue
            if self.levels[n].distance(pt) < COVER_TOL_M:
                return n
            n += 1
        if self.fixed_point:
            return None
        raise PlannerError(f"no plan within {self.config.max_pulls} pulls, and the reachable set still grows; raise "
                           "ReachabilityConfig.max_pulls")

    def solve_all(self) -> int:
        """Grow every level up to the fixed point (for maps, plots and warm starts); returns the number of levels."""
        while not self.fixed_point and len(self.levels) <= self.config.max_pulls:
            self._grow()
        return len(self.levels)

    # -------------------------------------------------------------------------------------- plans
    def plan(self, start: np.ndarray | tuple[float, float] | None = None, prefer: int | None = None) -> TetherPlan:
        """The plan with the fewest pulls from ``start`` (default the station's cargo start).

        ``prefer``: an anchor to keep for the first pull if it is one of the fewest-pull choices (the expert
        replanning while a tether already pulls).

        Raises:
            TetherInfeasibleError: the reachable set's fixed point does not contain the start (a proof).
            PlannerError: ``max_pulls`` reached while the set still grew.
        """
        t0 = time.perf_counter()
        st = self.station
        x = np.asarray(st.cargo.start_m if start is None else start, dtype=float)
        n = self.level_of(x)
        if n is None:
            reach = self.levels[-1]
            cert = {"levels": len(self.levels), "reachable_area_m2": float(reach.area),
                    "start_distance_m": float(reach.distance(Point(*x))), "fixed_point": True}
            raise TetherInfeasibleError(
                f"station {st.name!r}: no sequence of pulls carries the cargo from {x.round(3).tolist()} into the "
                f"goal box: the set of points that can reach it stops growing after {len(self.levels) - 1} pulls "
                f"({reach.area:.3g} m^2) and is {cert['start_distance_m']:.3g} m from the start", certificate=cert,
                groups=["anchors", "line of sight", "free space"])
        pulls: list[Pull] = []
        targets: list[int] = []  # per pull, the level it lands in
        here = x
        while n > 0:
            target = self.levels[n - 1]
            choice = self._best_pull(here, target, prefer if not pulls else None)
            if choice is None:
                raise PlannerError(f"internal: level {n} contains {here.round(6).tolist()} but no pull reaches level "
                                   f"{n - 1} from it (numerical trouble at a region boundary)")
            anchor, end = choice
            pulls.append(Pull(anchor=anchor, start_m=(float(here[0]), float(here[1])),
                              end_m=(float(end[0]), float(end[1]))))
            here = end
            level = self.level_of(here)
            if level is None:
                raise PlannerError(f"internal: the pull to {here.round(6).tolist()} lands in no level (numerical "
                                   "trouble at a region boundary)")
            n = level
            targets.append(n)
        plan = TetherPlan(station=st.name, start_m=(float(x[0]), float(x[1])), goal_box=st.goal_box, pulls=pulls,
                          pull_speed_mps=st.pull_speed_mps, switch_time_s=st.switch_time_s, method="reachability",
                          solve_time_s=time.perf_counter() - t0,
                          stats={"levels": len(self.levels), "setup_s": self.setup_s, "level_s": self.level_s,
                                 "clearance_m": self.config.clearance_m, "targets": targets})
        return with_hold(plan, st, self.usable)

    def pull_end(self, here: np.ndarray, anchor: int, level: int) -> np.ndarray | None:
        """Where a pull toward ``anchor`` from ``here`` should end to land in level ``level`` (deepest point of
        its segment in that level, as the forward read chooses); None if it misses the level."""
        if anchor not in self.seen or self.seen[anchor].is_empty or level >= len(self.levels):
            return None
        got = self._best_pull(np.asarray(here, float), self.levels[level], prefer=anchor, only=True)
        return None if got is None else got[1]

    def inside_free(self, point: np.ndarray, inset_m: float = 0.01) -> np.ndarray:
        """``point``, or if it is outside the free space the nearest point of it, ``inset_m`` further in."""
        pt = Point(float(point[0]), float(point[1]))
        if self.free.covers(pt):
            return np.asarray(point, float)
        inner = self.free.buffer(-inset_m)
        region = inner if not inner.is_empty else self.free
        q = shapely.ops.nearest_points(region, pt)[0]
        return np.array([q.x, q.y])

    def _best_pull(self, here: np.ndarray, target: BaseGeometry, prefer: int | None = None, only: bool = False
                   ) -> tuple[int, np.ndarray] | None:
        """The anchor and switch point of a pull from ``here`` into ``target``: deepest (capped), then shortest;
        ``prefer`` wins whenever it reaches the target at all."""
        best = None
        boundary = target.boundary
        order = ([prefer] if prefer in self.usable else []) + ([] if only else [a for a in self.usable if a != prefer])
        for a in order:
            seg = pull_segment(self.station, self.free, here, a, self.stop_m)
            if seg is None:
                continue
            hit = shapely.LineString(seg).intersection(target)
            parts = []
            for g in shapely.get_parts(hit):
                if g.geom_type == "LineString" and g.length > 0:
                    c = np.asarray(g.coords)
                    parts.append(c[0] + np.linspace(0.0, 1.0, 21)[:, None] * (c[-1] - c[0]))
                elif g.geom_type == "Point":
                    parts.append(np.asarray(g.coords))
            if not parts:
                continue
            pts = np.concatenate(parts)
            depth = shapely.distance(shapely.points(pts), boundary)
            depth = np.minimum(depth, shapely.distance(shapely.points(pts), self.free.boundary))
            length = np.linalg.norm(pts - here, axis=1)
            score = np.minimum(depth, self.config.depth_cap_m) * 1e3 - length + (1e7 if a == prefer else 0.0)
            k = int(np.argmax(score))
            if best is None or score[k] > best[0]:
                best = (score[k], a, pts[k])
        return None if best is None else (best[1], best[2])


def plan_reachability(station: Station, config: ReachabilityConfig | None = None,
                      start: tuple[float, float] | None = None) -> TetherPlan:
    """One plan with the fewest pulls (a fresh planner: the cold time)."""
    return ReachabilityPlanner(station, config).plan(start)
