"""Station: the map of an anchor-pull (tether) transport task, loaded from a validated TOML file.

The second transport mode of this package (an MSc thesis on hybrid motion planning for cargo in a space
station): robots attach to the cargo and to anchor points on the station's walls and pull the cargo toward
those anchors. A :class:`Station` holds everything a simulator or a planner needs: the station polygon, its
walls and anchors, the cargo, the goal box, the fleet and the STL task; its geometry (free space, line of
sight) is done with shapely.

Shipped stations live in ``impact_env/tether/stations/*.toml``; a user file has the same format (see
``docs/station_format.md``). As for scenarios, every field is checked on load (:mod:`impact_env.toml_fields`),
unknown keys are errors and every error names the field path, e.g.
``ScenarioError("cargo.radius_m must be > 0, got -0.2")``.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import shapely
from shapely.geometry import LineString, Point, Polygon

from impact_env import catalogue
from impact_env.errors import ScenarioError
from impact_env.geometry import ConvexPolygon
from impact_env.toml_fields import (
    Fields,
    check,
    check_horizon,
    load_toml,
    positive,
    read_header,
    task_formula,
    with_source,
)

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

CARGO = "cargo"  # the cargo's name in the STL task
GOAL = "goal"  # the goal box's name in the STL task
ON_WALL_TOL_M = 1e-6  # a listed anchor may be this far from its wall; it is then projected onto it
LOS_TOL_M = 1e-9  # line of sight tolerates this much: anchors sit on walls, and a tether may graze a corner


@dataclass(frozen=True)
class Anchor:
    """An anchor point on a wall: ``position_m`` (x, y) and the index of its wall in :attr:`Station.walls`."""

    index: int
    position_m: tuple[float, float]
    wall: int


@dataclass(frozen=True)
class Cargo:
    """The transported disc: mass (kg), radius (m), start position (m)."""

    mass_kg: float
    radius_m: float
    start_m: tuple[float, float]


@dataclass(frozen=True)
class Station:
    """Everything that defines one tether transport task. Build with :func:`load_station`.

    ``polygon`` is counter-clockwise without a repeated closing vertex; wall ``i`` joins ``polygon[i]`` and
    ``polygon[i + 1]`` (cyclically). A file written clockwise is reversed on load (see ``docs/station_format.md``
    for how its wall indices map).
    """

    name: str
    description: str
    polygon: tuple[tuple[float, float], ...]
    anchors: tuple[Anchor, ...]
    cargo: Cargo
    goal_box: tuple[float, float, float, float]  # xmin, xmax, ymin, ymax (m)
    n_robots: int
    k: int  # the most robots that may pull (or be attaching) at once
    pull_speed_mps: float  # w of the thesis's Eq. 5
    winch_force_limit_N: float
    stop_radius_m: float  # a tether is released when the cargo centre is this close to its anchor
    switch_time_s: float  # t_switch: time from an attach command to a pulling tether
    restitution: float  # cargo-wall
    tf_s: float
    task: str
    control_period_s: float = 1.0
    substeps: int = 10
    source: str = field(default="", compare=False)

    # -------------------------------------------------------------------------------------- geometry
    @property
    def walls(self) -> tuple[tuple[tuple[float, float], tuple[float, float]], ...]:
        """Wall ``i`` as its two end points, counter-clockwise (the station's interior on the left)."""
        p = self.polygon
        return tuple((p[i], p[(i + 1) % len(p)]) for i in range(len(p)))

    @property
    def n_anchors(self) -> int:
        return len(self.anchors)

    @cached_property
    def anchor_positions(self) -> np.ndarray:
        """(n_anchors, 2) anchor positions (m), in anchor index order."""
        return np.array([a.position_m for a in self.anchors], dtype=float).reshape(-1, 2)

    @cached_property
    def notches(self) -> np.ndarray:
        """(m, 2) the reflex vertices (interior angle > 180 deg): the only corners a tether can snag on."""
        p = np.array(self.polygon, dtype=float)
        before, after = p - np.roll(p, 1, axis=0), np.roll(p, -1, axis=0) - p
        cross = before[:, 0] * after[:, 1] - before[:, 1] * after[:, 0]
        return p[cross < 0.0].reshape(-1, 2)

    @cached_property
    def shapely_polygon(self) -> Polygon:
        """The station as a shapely Polygon (prepared for repeated predicates)."""
        poly = Polygon(self.polygon)
        shapely.prepare(poly)
        return poly

    @cached_property
    def _sight_polygon(self) -> Polygon:
        grown = self.shapely_polygon.buffer(LOS_TOL_M)
        shapely.prepare(grown)
        return grown

    def free_space(self, quad_segs: int = 16) -> Polygon:
        """Where the cargo centre may be with the whole disc inside the station: the polygon shrunk by the radius.

        This is the erosion of the polygon by the cargo disc (``buffer(-radius)`` with round joins). Around a
        notch (reflex vertex) its boundary is an arc of the cargo radius, which shapely approximates with
        ``quad_segs`` chords per quarter circle; chords cut inside the arc by at most
        ``radius * (1 - cos(pi / (4 * quad_segs)))`` (0.4 mm for the 0.3 m cargo at 16). May be a
        MultiPolygon if a passage is narrower than the cargo.
        """
        return self.shapely_polygon.buffer(-self.cargo.radius_m, quad_segs=quad_segs, join_style="round")

    @cached_property
    def goal_polygon(self) -> ConvexPolygon:
        return ConvexPolygon.from_box(*self.goal_box)

    @property
    def goal_center_m(self) -> tuple[float, float]:
        x0, x1, y0, y1 = self.goal_box
        return (0.5 * (x0 + x1), 0.5 * (y0 + y1))

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(xmin, xmax, ymin, ymax) of the polygon (m)."""
        xs, ys = zip(*self.polygon)
        return min(xs), max(xs), min(ys), max(ys)

    def region_map(self) -> dict[str, ConvexPolygon]:
        """Name -> region for the STL task: only ``goal``."""
        return {GOAL: self.goal_polygon}

    @property
    def formula(self):
        """The task as an STL syntax tree (parsed on first use)."""
        from impact_env.stl import parse

        return parse(self.task)

    def line_of_sight(self, point_m: tuple[float, float] | np.ndarray, anchors: Any = None) -> np.ndarray:
        """Boolean mask: which anchors a tether from ``point_m`` reaches with no wall in between.

        A tether sees its anchor when the segment from the point to the anchor lies in the closed station
        polygon: it may touch a wall or graze a corner, but not pass outside. The test allows ``LOS_TOL_M``
        (1 nm) of rounding, since an anchor sits on a wall and a grazing segment passes exactly through a corner.

        Args:
            point_m: (x, y) of the tether's cargo end (the cargo centre), m.
            anchors: anchor indices to test (default: all), any sequence of ints.
        """
        idx = np.arange(self.n_anchors) if anchors is None else np.asarray(anchors, dtype=int).reshape(-1)
        if idx.size == 0:
            return np.zeros(0, dtype=bool)
        p = np.asarray(point_m, dtype=float).reshape(2)
        a = self.anchor_positions[idx]
        coords = np.stack([a, np.broadcast_to(p, a.shape)], axis=1)
        return np.asarray(shapely.covers(self._sight_polygon, shapely.linestrings(coords)), dtype=bool)

    def cargo_inside(self, point_m: tuple[float, float], tol_m: float = 1e-9) -> bool:
        """Whether the cargo disc centred at ``point_m`` lies inside the station (up to ``tol_m``)."""
        poly = self.shapely_polygon
        pt = Point(float(point_m[0]), float(point_m[1]))
        return bool(poly.covers(pt)) and float(poly.exterior.distance(pt)) >= self.cargo.radius_m - tol_m


# ----------------------------------------------------------------------------------------------- loading


def station_names() -> list[str]:
    """Names of the stations shipped with the package."""
    return catalogue.names_of("station")


def is_station_file(name_or_path: str | Path) -> bool:
    """True for a shipped station name or a TOML file with a ``[station]`` table (the CLI's dispatch test)."""
    name = str(name_or_path)
    if name in station_names():
        return True
    path = Path(name_or_path)
    if not path.is_file():
        return False
    try:
        return isinstance(tomllib.loads(path.read_text(encoding="utf-8")).get("station"), dict)
    except (tomllib.TOMLDecodeError, UnicodeDecodeError, OSError):
        return False


def load_station(name_or_path: str | Path) -> Station:
    """Load a shipped station by name (``"L"``) or a TOML file by path, validated.

    Raises:
        ScenarioError: unknown name, unreadable file, text that is not UTF-8, invalid TOML or any invalid field.
    """
    data, source = load_toml(name_or_path, "station")
    return station_from_dict(data, source=source)


def station_from_dict(data: dict, source: str = "<dict>") -> Station:
    """Validate a parsed TOML document and build the Station; see :func:`load_station`."""
    return with_source(_build, data, source)


def _build(data: dict, source: str) -> Station:
    top = Fields(data, "")
    header = read_header(top, default_period_s=1.0)
    tf = header.tf_s
    task = top.get("task", None, kind="str")

    st = Fields(top.get("station"), "station")
    polygon, file_to_ccw = _polygon(st.get("polygon"), "station.polygon")
    st.finish()

    cg = Fields(top.get("cargo"), "cargo")
    cargo = Cargo(mass_kg=positive(cg.get("mass_kg", kind="float"), "cargo.mass_kg"),
                  radius_m=positive(cg.get("radius_m", kind="float"), "cargo.radius_m"),
                  start_m=cg.get("start_m", kind="vec2"))
    cg.finish()

    goal_box = _goal(top.get("goal"))

    rb = Fields(top.get("robots"), "robots")
    n_robots = rb.get("count", kind="int")
    if n_robots < 1:
        raise ScenarioError(f"robots.count must be >= 1, got {n_robots}")
    k = rb.get("max_active", n_robots, kind="int")
    if not 1 <= k <= n_robots:
        raise ScenarioError(f"robots.max_active must be in 1..robots.count = {n_robots}, got {k}")
    w = positive(rb.get("pull_speed_mps", kind="float"), "robots.pull_speed_mps")
    winch = positive(rb.get("winch_force_limit_N", kind="float"), "robots.winch_force_limit_N")
    stop = positive(rb.get("stop_radius_m", kind="float"), "robots.stop_radius_m")
    t_switch = positive(rb.get("switch_time_s", kind="float"), "robots.switch_time_s", allow_zero=True)
    rb.finish()

    anchors = _anchors(top.get("anchors"), polygon, file_to_ccw)
    top.finish()

    if task is None:
        task = f"F[0,{_fmt(tf)}] in({CARGO}, {GOAL})"
    station = Station(
        name=header.name, description=header.description, polygon=polygon, anchors=anchors, cargo=cargo,
        goal_box=goal_box, n_robots=n_robots, k=k, pull_speed_mps=w, winch_force_limit_N=winch, stop_radius_m=stop,
        switch_time_s=t_switch, restitution=header.restitution, tf_s=tf, task=task,
        control_period_s=header.control_period_s, substeps=header.substeps, source=source,
    )
    _check_placement(station)
    _check_rates(station)
    _check_task(station)
    return station


def _fmt(x: float) -> str:
    return str(int(x)) if x == int(x) else repr(x)


def _polygon(value: Any, where: str) -> tuple[tuple[tuple[float, float], ...], list[int]]:
    """Validated counter-clockwise vertices, and for each wall as written its index after normalisation."""
    if not isinstance(value, list) or len(value) < 3:
        raise ScenarioError(f"{where} must be a list of at least 3 vertices [[x, y], ...], got {value!r}")
    pts = [check(v, "vec2", f"{where}[{i}]") for i, v in enumerate(value)]
    n = len(pts)
    if pts[0] == pts[-1]:
        raise ScenarioError(f"{where}: the last vertex repeats the first; list each vertex once (the polygon "
                            "closes itself)")
    seen: dict[tuple[float, float], int] = {}
    for i, p in enumerate(pts):
        if p in seen:
            raise ScenarioError(f"{where}[{i}] = {list(p)} repeats vertex {seen[p]}; each vertex must be distinct")
        seen[p] = i
    for i in range(n):
        a, b = pts[i], pts[(i + 1) % n]
        if math.dist(a, b) < 1e-9:
            raise ScenarioError(f"{where}: wall {i} from {list(a)} to {list(b)} has zero length")
    xs, ys = np.array([p[0] for p in pts]), np.array([p[1] for p in pts])
    if np.linalg.matrix_rank(np.stack([xs - xs.mean(), ys - ys.mean()]), tol=1e-9) < 2:
        raise ScenarioError(f"{where} has zero area: all its vertices are on one line")
    # self-intersection: any two walls that are not neighbours must not meet; neighbours only at their joint
    lines = [LineString([pts[i], pts[(i + 1) % n]]) for i in range(n)]
    for i in range(n):
        for j in range(i + 1, n):
            inter = lines[i].intersection(lines[j])
            if inter.is_empty:
                continue
            adjacent = j == i + 1 or (i == 0 and j == n - 1)
            if adjacent and inter.geom_type == "Point":
                continue
            at = inter.representative_point()
            what = "overlap" if adjacent or inter.geom_type != "Point" else "cross"
            raise ScenarioError(f"{where} is not simple: walls {i} ({list(pts[i])} -> {list(pts[(i + 1) % n])}) and "
                                f"{j} ({list(pts[j])} -> {list(pts[(j + 1) % n])}) {what} at "
                                f"[{at.x:.6g}, {at.y:.6g}]; the station must be a simple polygon without holes")
    area2 = float(np.sum(xs * np.roll(ys, -1) - np.roll(xs, -1) * ys))
    if abs(area2) < 1e-12:
        raise ScenarioError(f"{where} has zero area")
    if area2 > 0:
        return tuple(pts), list(range(n))
    # clockwise: reverse, keeping the first vertex; wall i as written becomes wall n - 1 - i
    return tuple([pts[0]] + pts[:0:-1]), [n - 1 - i for i in range(n)]


def _goal(value: Any) -> tuple[float, float, float, float]:
    g = Fields(value, "goal")
    box = g.get("box", None, kind="box")
    center = g.get("center_m", None, kind="vec2")
    half = g.get("half_size_m", None, kind="float")
    g.finish()
    if (box is None) == (center is None):
        raise ScenarioError("goal needs exactly one of 'box = [xmin, xmax, ymin, ymax]' or "
                            "'center_m = [x, y]' (with 'half_size_m')")
    if box is not None:
        if half is not None:
            raise ScenarioError("goal.half_size_m goes with goal.center_m, not with goal.box")
        return box
    if half is None:
        raise ScenarioError("goal.half_size_m is required with goal.center_m (the box is center +- half_size_m)")
    positive(half, "goal.half_size_m")
    return (center[0] - half, center[0] + half, center[1] - half, center[1] + half)


def _anchors(value: Any, polygon: tuple[tuple[float, float], ...], file_to_ccw: list[int]) -> tuple[Anchor, ...]:
    """The spacing rule on the chosen walls and the listed points, sorted along the walls."""
    f = Fields(value, "anchors")
    spacing = f.get("spacing_m", None, kind="float")
    walls = f.get("walls", None)
    points = f.get("points", None)
    f.finish()
    if walls is not None and spacing is None:
        raise ScenarioError("anchors.walls selects the walls of the spacing rule; it needs anchors.spacing_m")
    if spacing is None and points is None:
        raise ScenarioError("anchors needs 'spacing_m' (one anchor per part of every wall, see the format doc) "
                            "and/or 'points = [[x, y], ...]'")
    n = len(polygon)
    found: list[tuple[int, float, tuple[float, float]]] = []  # (wall, position along it, point)
    if spacing is not None:
        positive(spacing, "anchors.spacing_m")
        if walls is None:
            chosen = list(range(n))
        else:
            if not isinstance(walls, list) or not walls:
                raise ScenarioError(f"anchors.walls must be a non-empty list of wall indices, got {walls!r}")
            chosen = []
            for i, wi in enumerate(walls):
                wi = check(wi, "int", f"anchors.walls[{i}]")
                if not 0 <= wi < n:
                    raise ScenarioError(f"anchors.walls[{i}] = {wi} is not a wall; walls are 0..{n - 1} (wall i joins "
                                        "station.polygon[i] and polygon[i + 1] as written)")
                if file_to_ccw[wi] in chosen:
                    raise ScenarioError(f"anchors.walls[{i}] = {wi} is listed twice")
                chosen.append(file_to_ccw[wi])
        for wall in sorted(chosen):
            a, b = polygon[wall], polygon[(wall + 1) % n]
            parts = max(1, math.floor(math.dist(a, b) / spacing + 1e-9))
            for j in range(parts):
                s = (j + 0.5) / parts
                found.append((wall, s, (a[0] + s * (b[0] - a[0]), a[1] + s * (b[1] - a[1]))))
    if points is not None:
        if not isinstance(points, list):
            raise ScenarioError(f"anchors.points must be a list of [x, y] points, got {points!r}")
        for i, pv in enumerate(points):
            p = check(pv, "vec2", f"anchors.points[{i}]")
            best = None
            for wall in range(n):
                a, b = polygon[wall], polygon[(wall + 1) % n]
                ex, ey = b[0] - a[0], b[1] - a[1]
                s = min(1.0, max(0.0, ((p[0] - a[0]) * ex + (p[1] - a[1]) * ey) / (ex * ex + ey * ey)))
                q = (a[0] + s * ex, a[1] + s * ey)
                d = math.dist(p, q)
                if best is None or d < best[0]:
                    best = (d, wall, s, q)
            d, wall, s, q = best  # type: ignore[misc]  # a polygon has walls: best is set
            if d > ON_WALL_TOL_M:
                raise ScenarioError(f"anchors.points[{i}] = {list(p)} is not on a wall (nearest wall {wall} is "
                                    f"{d:.6g} m away); anchors must lie on the station's boundary")
            found.append((wall, s, (p[0], p[1]) if d == 0.0 else q))
    found.sort(key=lambda t: (t[0], t[1]))
    for (w0, _, p0), (w1, _, p1) in zip(found, found[1:]):
        if math.dist(p0, p1) < 1e-9:
            raise ScenarioError(f"anchors: two anchors at {list(p0)} (walls {w0} and {w1}); listed points must not "
                                "repeat each other or an anchor of the spacing rule")
    return tuple(Anchor(index=i, position_m=p, wall=w) for i, (w, _, p) in enumerate(found))


def _check_placement(station: Station) -> None:
    poly = station.shapely_polygon
    r = station.cargo.radius_m
    start = station.cargo.start_m
    pt = Point(*start)
    clearance = float(poly.exterior.distance(pt))
    if not poly.covers(pt) or clearance < r - 1e-9:
        where = "outside the station" if not poly.covers(pt) else f"{clearance:.4g} m from a wall"
        raise ScenarioError(f"cargo.start_m = {list(start)} puts the cargo disc (radius {r} m) partly outside the "
                            f"station: its centre is {where}; the centre must be at least the radius from every wall")
    box = shapely.box(station.goal_box[0], station.goal_box[2], station.goal_box[1], station.goal_box[3])
    if not poly.covers(box):
        raise ScenarioError(f"goal box {list(station.goal_box)} is not inside the station polygon")
    if not station.free_space().intersects(box):
        raise ScenarioError(f"goal box {list(station.goal_box)} cannot hold the cargo centre: every point of it is "
                            f"closer than the cargo radius ({r} m) to a wall")
    if station.stop_radius_m < r:
        raise ScenarioError(f"robots.stop_radius_m = {station.stop_radius_m} must be >= cargo.radius_m = {r}: a "
                            "tether is released only this close to its anchor, so a smaller radius would drive the "
                            "cargo into the wall first")


def _check_rates(station: Station) -> None:
    """The tension law of the ``force`` fidelity and tunnelling bound the substep length.

    ``force`` sets the tension to ``F_max * (1 - v_r / w)``; an explicit step of it moves the cargo's
    radial speed by ``dt F_max / (m w)`` of the shortfall, which must not exceed 1 (it would overshoot w).
    The cargo moves at most ``k w`` under Eq. 5; a substep must move it less than a quarter radius.
    """
    dt = station.control_period_s / station.substeps
    gain = dt * station.winch_force_limit_N / (station.cargo.mass_kg * station.pull_speed_mps)
    if gain > 1.0:
        need = math.ceil(station.control_period_s * station.winch_force_limit_N
                         / (station.cargo.mass_kg * station.pull_speed_mps))
        raise ScenarioError(f"substeps = {station.substeps} is too few for the winch: a substep of {dt:g} s would let "
                            f"the tension law change the cargo's speed by {gain:.3g} of its shortfall (must be <= 1); "
                            f"use substeps >= {need}")
    step = station.k * station.pull_speed_mps * dt
    if step > 0.25 * station.cargo.radius_m:
        need = math.ceil(station.k * station.pull_speed_mps * station.control_period_s
                         / (0.25 * station.cargo.radius_m))
        raise ScenarioError(f"substeps = {station.substeps} is too few: at k * w = "
                            f"{station.k * station.pull_speed_mps:g} m/s the cargo moves {step:.3g} m per substep, "
                            f"more than a quarter of its radius; use substeps >= {need}")


def _check_task(station: Station) -> None:
    formula = task_formula(station)
    if formula.bodies() - {CARGO}:
        raise ScenarioError(f"task names body {sorted(formula.bodies() - {CARGO})[0]!r}; a station task can only "
                            f"name the body {CARGO!r}")
    if formula.regions() - {GOAL}:
        raise ScenarioError(f"task names region {sorted(formula.regions() - {GOAL})[0]!r}; a station task can only "
                            f"name the region {GOAL!r}")
    check_horizon(formula, station.tf_s, example=f"'F[0,{_fmt(station.tf_s)}] in({CARGO}, {GOAL})'")
