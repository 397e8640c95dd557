"""Station: the map of an anchor-pull (tether) transport task, loaded from a validated TOML file.

The second transport mode of this package (an MSc thesis on hybrid motion planning for cargo in a space
station): robots attach to the cargo and to anchor points on the station's walls and pull the cargo toward
those anchors. A :class:`Station` holds everything a simulator or a planner needs: the station polygon, its
walls and anchors, the cargo, the goal box and how long the cargo must rest in it, the fleet and the STL
task; its geometry (free space, line of sight) is done with shapely.

Shipped stations live in ``impact_env/tether/stations/*.toml``; a user file has the same format (see
``docs/station_format.md``). As for scenarios, every field is checked on load (:mod:`impact_env.toml_fields`,
the sizes and ranges of :mod:`impact_env.tether.limits`), unknown keys are errors and every error names the
field path, e.g. ``ScenarioError("cargo.radius_m must be > 0, got -0.2")``.
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
from shapely.geometry import Point, Polygon

from impact_env import catalogue, limits
from impact_env.errors import ScenarioError, STLError, brief
from impact_env.geometry import ConvexPolygon
from impact_env.tether import limits as tl
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
DRIFT = "drift"  # the task's name for the cargo's velocity times the drift time: where it would drift to (m)
GOAL = "goal"  # the goal box's name in the STL task
REST = "rest"  # the task's name for the drifts of a cargo at rest: a disc of rest_speed_mps * drift_time_s
ON_WALL_TOL_M = 1e-6  # a listed anchor may be this far from its wall; it is then projected onto it
LOS_TOL_M = 1e-9  # line of sight tolerates this much: anchors sit on walls, and a tether may graze a corner
DEFAULT_HOLD_S = 30.0
DEFAULT_REST_SPEED_MPS = 0.02
REST_SIDES = 16  # the rest region is the regular 16-gon inscribed in the rest-speed circle


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

    The task (:attr:`task`) is by default "deliver and hold": reach the goal box and stay in it at rest for
    ``hold_s`` seconds, ``F[0,tf - hold] G[0,hold] (in(cargo, goal) & in(drift, rest))``. ``drift`` is the
    cargo's velocity times :attr:`drift_time_s` (where it would drift to in that time, m) and ``rest`` the
    disc of drifts of a cargo slower than ``rest_speed_mps`` (a 16-gon inscribed in it), so both predicates'
    robustness is in metres. With ``hold_s = 0`` the default is :attr:`reach_task`, ``F[0,tf] in(cargo,
    goal)`` (the task of the ``-v0`` environments).
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
    hold_s: float = DEFAULT_HOLD_S  # how long the cargo must stay in the goal box at rest (s)
    rest_speed_mps: float = DEFAULT_REST_SPEED_MPS  # at rest: slower than this (m/s)
    robot_names: tuple[str, ...] = ()  # the PettingZoo agents' names, R1 .. Rn by default

    def __setstate__(self, state: dict) -> None:
        """A Station pickled before the hold (0.2) had no hold: its task is the one it was saved with."""
        state = {"hold_s": 0.0, "rest_speed_mps": DEFAULT_REST_SPEED_MPS, **state}
        if not state.get("robot_names"):
            state["robot_names"] = default_robot_names(state["n_robots"])
        self.__dict__.update(state)

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
    def anchor_points(self) -> tuple[tuple[float, float], ...]:
        """The anchor positions as (x, y) float pairs (what the physics' hot loop reads)."""
        return tuple((float(a.position_m[0]), float(a.position_m[1])) for a in self.anchors)

    @cached_property
    def wall_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Wall start points, wall vectors (each (n, 2)) and squared lengths (n,): the physics' wall contacts."""
        ends = np.array(self.walls, dtype=float)
        starts, vectors = ends[:, 0], ends[:, 1] - ends[:, 0]
        return starts, vectors, np.einsum("ij,ij->i", vectors, vectors)

    def sees(self, x: float, y: float, anchors: list[int]) -> np.ndarray:
        """:meth:`line_of_sight` from (x, y) of a few anchors (bool, len(anchors)), without its input handling."""
        points = self.anchor_points
        return shapely.covers(self._sight_polygon, shapely.linestrings([[points[a], (x, y)] for a in anchors]))

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
        return ConvexPolygon.from_box(*self.goal_box, where="goal")

    @property
    def goal_center_m(self) -> tuple[float, float]:
        x0, x1, y0, y1 = self.goal_box
        return (0.5 * (x0 + x1), 0.5 * (y0 + y1))

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(xmin, xmax, ymin, ymax) of the polygon (m)."""
        xs, ys = zip(*self.polygon)
        return min(xs), max(xs), min(ys), max(ys)

    # ------------------------------------------------------------------------------------------ task
    @property
    def drift_time_s(self) -> float:
        """The time scale of the ``drift`` body (s): the hold time, or 1 s without one."""
        return self.hold_s if self.hold_s > 0 else 1.0

    @cached_property
    def rest_polygon(self) -> ConvexPolygon:
        """The ``rest`` region: the regular 16-gon inscribed in the circle of drifts ``rest_speed * drift_time``,
        so a drift inside it means a speed below ``rest_speed_mps``."""
        r = self.rest_speed_mps * self.drift_time_s
        angles = 2.0 * math.pi * (np.arange(REST_SIDES) + 0.5) / REST_SIDES
        return ConvexPolygon.from_vertices(np.stack([r * np.cos(angles), r * np.sin(angles)], axis=1), where="rest")

    @property
    def reach_task(self) -> str:
        """"Eventually in the goal box": the station task before the hold (the ``-v0`` environments')."""
        return f"F[0,{_fmt(self.tf_s)}] in({CARGO}, {GOAL})"

    @property
    def hold_task(self) -> str:
        """"Reach the goal box and stay in it at rest for ``hold_s``": the default task."""
        return (f"F[0,{_fmt(self.tf_s - self.hold_s)}] G[0,{_fmt(self.hold_s)}] "
                f"(in({CARGO}, {GOAL}) & in({DRIFT}, {REST}))")

    @property
    def default_task(self) -> str:
        """The task a file without ``task`` gets: :attr:`hold_task`, or :attr:`reach_task` with ``hold_s = 0``."""
        return self.hold_task if self.hold_s > 0 else self.reach_task

    def region_map(self) -> dict[str, ConvexPolygon]:
        """Name -> region for the STL task: ``goal`` and ``rest``."""
        return {GOAL: self.goal_polygon, REST: self.rest_polygon}

    def task_positions(self, x: float, y: float, vx: float, vy: float) -> dict[str, tuple[float, float]]:
        """The STL task's bodies for a cargo at (x, y) moving at (vx, vy): ``cargo`` and ``drift``."""
        t = self.drift_time_s
        return {CARGO: (x, y), DRIFT: (vx * t, vy * t)}

    @property
    def formula(self):
        """The task as an STL syntax tree (parsed on first use)."""
        from impact_env.stl import parse

        return parse(self.task)

    # ------------------------------------------------------------------------------------- queries
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

    def cargo_inside_many(self, points_m: np.ndarray, tol_m: float = 1e-9) -> np.ndarray:
        """:meth:`cargo_inside` of (n, 2) points at once (bool, n)."""
        pts = shapely.points(np.asarray(points_m, dtype=float).reshape(-1, 2))
        poly = self.shapely_polygon
        return np.asarray(shapely.covers(poly, pts) & (shapely.distance(poly.exterior, pts) >= self.cargo.radius_m
                                                        - tol_m), dtype=bool)


def default_robot_names(n: int) -> tuple[str, ...]:
    """``R1 .. Rn``: the robots' names when a station file lists none (the impact world's convention)."""
    return tuple(f"R{i + 1}" for i in range(n))


# ----------------------------------------------------------------------------------------------- loading


def station_names() -> list[str]:
    """Names of the stations shipped with the package."""
    return catalogue.names_of("station")


def is_station_file(name_or_path: str | Path) -> bool:
    """True for a shipped station name or a TOML file with a ``[station]`` table (the CLI's dispatch test)."""
    if not isinstance(name_or_path, (str, Path)):
        return False
    name = str(name_or_path)
    if name in station_names():
        return True
    try:
        path = Path(name_or_path)
        if not path.is_file():
            return False
        return isinstance(tomllib.loads(path.read_text(encoding="utf-8")).get("station"), dict)
    except (tomllib.TOMLDecodeError, UnicodeDecodeError, OSError, ValueError, RecursionError):
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
    if not isinstance(data, dict):
        raise ScenarioError(f"{source}: a station is a table of fields, got {type(data).__name__}")
    return with_source(_build, data, source)


def _build(data: dict, source: str) -> Station:
    top = Fields(data, "")
    header = read_header(top, default_period_s=1.0)
    tf = header.tf_s
    limits.check_timing(tf, header.control_period_s, header.substeps)
    if header.control_period_s < tl.MIN_CONTROL_PERIOD_S:
        raise ScenarioError(f"control_period_s must be >= {tl.MIN_CONTROL_PERIOD_S:g} s, got "
                            f"{header.control_period_s:g}")
    if tf < header.control_period_s:
        raise ScenarioError(f"tf_s = {tf:g} s is shorter than one control period ({header.control_period_s:g} s): "
                            "the episode would have no step")
    task = top.get("task", None, kind="str")

    st = Fields(top.get("station"), "station")
    polygon, file_to_ccw = _polygon(st.get("polygon"), "station.polygon")
    st.finish()

    cg = Fields(top.get("cargo"), "cargo")
    cargo = Cargo(mass_kg=tl.check_mass(cg.get("mass_kg", kind="float"), "cargo.mass_kg"),
                  radius_m=_length(cg.get("radius_m", kind="float"), "cargo.radius_m"),
                  start_m=cg.get("start_m", kind="vec2"))
    cg.finish()
    tl.check_coordinates([cargo.start_m], "cargo.start_m")

    goal_box, hold, rest = _goal(top.get("goal"), tf, header.control_period_s)

    rb = Fields(top.get("robots"), "robots")
    n_robots = rb.get("count", kind="int")
    if n_robots < 1:
        raise ScenarioError(f"robots.count must be >= 1, got {n_robots}")
    if n_robots > tl.MAX_ROBOTS:
        raise ScenarioError(f"robots.count = {n_robots}: at most {tl.MAX_ROBOTS} robots are supported")
    k = rb.get("max_active", n_robots, kind="int")
    if not 1 <= k <= n_robots:
        raise ScenarioError(f"robots.max_active must be in 1..robots.count = {n_robots}, got {k}")
    w = tl.check_range(rb.get("pull_speed_mps", kind="float"), "robots.pull_speed_mps", tl.MIN_SPEED_MPS,
                       tl.MAX_SPEED_MPS, "m/s")
    winch = tl.check_range(rb.get("winch_force_limit_N", kind="float"), "robots.winch_force_limit_N",
                           tl.MIN_FORCE_N, tl.MAX_FORCE_N, "N")
    stop = _length(rb.get("stop_radius_m", kind="float"), "robots.stop_radius_m")
    t_switch = positive(rb.get("switch_time_s", kind="float"), "robots.switch_time_s", allow_zero=True)
    if t_switch > tf:
        raise ScenarioError(f"robots.switch_time_s = {t_switch:g} s is longer than the episode (tf_s = {tf:g} s)")
    names = _robot_names(rb.get("names", None), n_robots)
    rb.finish()

    anchors = _anchors(top.get("anchors"), polygon, file_to_ccw)
    top.finish()

    station = Station(
        name=header.name, description=header.description, polygon=polygon, anchors=anchors, cargo=cargo,
        goal_box=goal_box, n_robots=n_robots, k=k, pull_speed_mps=w, winch_force_limit_N=winch, stop_radius_m=stop,
        switch_time_s=t_switch, restitution=header.restitution, tf_s=tf, task=task or "",
        control_period_s=header.control_period_s, substeps=header.substeps, source=source, hold_s=hold,
        rest_speed_mps=rest, robot_names=names,
    )
    if task is None:
        object.__setattr__(station, "task", station.default_task)
    _check_placement(station)
    _check_rates(station)
    _check_task(station)
    return station


def _fmt(x: float) -> str:
    return str(int(x)) if x == int(x) else repr(x)


def _length(value: float, where: str) -> float:
    """A length (m) of at least a millimetre and at most the coordinate range."""
    return tl.check_range(value, where, tl.MIN_LENGTH_M, 2 * tl.MAX_COORDINATE_M, "m")


def _robot_names(value: Any, n: int) -> tuple[str, ...]:
    if value is None:
        return default_robot_names(n)
    if not isinstance(value, list) or len(value) != n:
        raise ScenarioError(f"robots.names must list one name per robot ({n}), got {brief(value)}")
    names = tuple(check(v, "name", f"robots.names[{i}]") for i, v in enumerate(value))
    if len(set(names)) != n:
        raise ScenarioError(f"robots.names must be distinct, got {list(names)}")
    return names


def _polygon(value: Any, where: str) -> tuple[tuple[tuple[float, float], ...], list[int]]:
    """Validated counter-clockwise vertices, and for each wall as written its index after normalisation."""
    if not isinstance(value, list) or len(value) < 3:
        raise ScenarioError(f"{where} must be a list of at least 3 vertices [[x, y], ...], got {brief(value)}")
    if len(value) > tl.MAX_VERTICES:
        raise ScenarioError(f"{where} has {len(value)} vertices; at most {tl.MAX_VERTICES} are supported")
    pts = [check(v, "vec2", f"{where}[{i}]") for i, v in enumerate(value)]
    tl.check_coordinates(pts, where)
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
        if math.dist(a, b) < tl.MIN_LENGTH_M:
            raise ScenarioError(f"{where}: wall {i} from {list(a)} to {list(b)} is shorter than "
                                f"{tl.MIN_LENGTH_M:g} m")
    xs, ys = np.array([p[0] for p in pts]), np.array([p[1] for p in pts])
    if np.linalg.matrix_rank(np.stack([xs - xs.mean(), ys - ys.mean()]), tol=1e-9) < 2:
        raise ScenarioError(f"{where} has zero area: all its vertices are on one line")
    tl.wall_crossing(pts, where)
    area2 = tl.polygon_area2(pts)
    if abs(area2) < 2 * tl.MIN_LENGTH_M ** 2:
        raise ScenarioError(f"{where} has zero area")
    if area2 > 0:
        return tuple(pts), list(range(n))
    # clockwise: reverse, keeping the first vertex; wall i as written becomes wall n - 1 - i
    return tuple([pts[0]] + pts[:0:-1]), [n - 1 - i for i in range(n)]


def _goal(value: Any, tf_s: float, period_s: float) -> tuple[tuple[float, float, float, float], float, float]:
    """The goal box, the hold time (s) and the rest speed (m/s)."""
    g = Fields(value, "goal")
    box = g.get("box", None, kind="box")
    center = g.get("center_m", None, kind="vec2")
    half = g.get("half_size_m", None, kind="float")
    hold = positive(g.get("hold_s", DEFAULT_HOLD_S, kind="float"), "goal.hold_s", allow_zero=True)
    rest = tl.check_range(g.get("rest_speed_mps", DEFAULT_REST_SPEED_MPS, kind="float"), "goal.rest_speed_mps",
                          tl.MIN_SPEED_MPS, tl.MAX_SPEED_MPS, "m/s")
    g.finish()
    if hold > tf_s - period_s:
        raise ScenarioError(f"goal.hold_s = {hold:g} s leaves less than one control period of tf_s = {tf_s:g} s to "
                            "reach the goal; lower it (0: no hold, the task is to reach the goal once)")
    if (box is None) == (center is None):
        raise ScenarioError("goal needs exactly one of 'box = [xmin, xmax, ymin, ymax]' or "
                            "'center_m = [x, y]' (with 'half_size_m')")
    if box is not None:
        if half is not None:
            raise ScenarioError("goal.half_size_m goes with goal.center_m, not with goal.box")
        tl.check_coordinates([(box[0], box[2]), (box[1], box[3])], "goal.box")
        if min(box[1] - box[0], box[3] - box[2]) < tl.MIN_LENGTH_M:
            raise ScenarioError(f"goal.box {list(box)} must be at least {tl.MIN_LENGTH_M:g} m wide and high")
        return box, hold, rest
    if half is None:
        raise ScenarioError("goal.half_size_m is required with goal.center_m (the box is center +- half_size_m)")
    tl.check_coordinates([center], "goal.center_m")
    tl.check_range(half, "goal.half_size_m", tl.MIN_LENGTH_M / 2, tl.MAX_COORDINATE_M, "m")
    return (center[0] - half, center[0] + half, center[1] - half, center[1] + half), hold, rest


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
        _length(spacing, "anchors.spacing_m")
        if walls is None:
            chosen = list(range(n))
        else:
            if not isinstance(walls, list) or not walls:
                raise ScenarioError(f"anchors.walls must be a non-empty list of wall indices, got {brief(walls)}")
            chosen = []
            for i, wi in enumerate(walls):
                wi = check(wi, "int", f"anchors.walls[{i}]")
                if not 0 <= wi < n:
                    raise ScenarioError(f"anchors.walls[{i}] = {wi} is not a wall; walls are 0..{n - 1} (wall i joins "
                                        "station.polygon[i] and polygon[i + 1] as written)")
                if file_to_ccw[wi] in chosen:
                    raise ScenarioError(f"anchors.walls[{i}] = {wi} is listed twice")
                chosen.append(file_to_ccw[wi])
        lengths = [math.dist(polygon[wall], polygon[(wall + 1) % n]) for wall in chosen]
        count = tl.anchors_of_spacing(lengths, spacing)
        if count > tl.MAX_ANCHORS:
            raise ScenarioError(f"anchors.spacing_m = {spacing:g} m puts more than {tl.MAX_ANCHORS} anchors on the "
                                f"walls ({sum(lengths):.4g} m); at most {tl.MAX_ANCHORS} are supported")
        for wall in sorted(chosen):
            a, b = polygon[wall], polygon[(wall + 1) % n]
            parts = max(1, math.floor(math.dist(a, b) / spacing + 1e-9))
            for j in range(parts):
                s = (j + 0.5) / parts
                found.append((wall, s, (a[0] + s * (b[0] - a[0]), a[1] + s * (b[1] - a[1]))))
    if points is not None:
        if not isinstance(points, list):
            raise ScenarioError(f"anchors.points must be a list of [x, y] points, got {brief(points)}")
        if len(points) + len(found) > tl.MAX_ANCHORS:
            raise ScenarioError(f"anchors: {len(points) + len(found)} anchors; at most {tl.MAX_ANCHORS} are "
                                "supported")
        for i, pv in enumerate(points):
            p = check(pv, "vec2", f"anchors.points[{i}]")
            tl.check_coordinates([p], "anchors.points")
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
        need = station.control_period_s * station.winch_force_limit_N / (station.cargo.mass_kg
                                                                         * station.pull_speed_mps)
        raise ScenarioError(f"substeps = {station.substeps} is too few for the winch: a substep of {dt:g} s would let "
                            f"the tension law change the cargo's speed by {gain:.3g} of its shortfall (must be <= 1); "
                            + _need(need))
    step = station.k * station.pull_speed_mps * dt
    if step > 0.25 * station.cargo.radius_m:
        need = station.k * station.pull_speed_mps * station.control_period_s / (0.25 * station.cargo.radius_m)
        raise ScenarioError(f"substeps = {station.substeps} is too few: at k * w = "
                            f"{station.k * station.pull_speed_mps:g} m/s the cargo moves {step:.3g} m per substep, "
                            f"more than a quarter of its radius; " + _need(need))


def _need(substeps: float) -> str:
    if substeps <= limits.MAX_SUBSTEPS:
        return f"use substeps >= {math.ceil(substeps)}"
    return (f"even the maximum of {limits.MAX_SUBSTEPS} substeps is too few (it would need {substeps:.3g}): shorten "
            "control_period_s, or change the winch force, cargo mass or pulling speed")


def _check_task(station: Station) -> None:
    from impact_env.stl.formula import horizon_steps

    formula = task_formula(station)
    bodies, regions = {CARGO, DRIFT}, {GOAL, REST}
    if formula.bodies() - bodies:
        raise ScenarioError(f"task names body {sorted(formula.bodies() - bodies)[0]!r}; a station task can only "
                            f"name the bodies {CARGO!r} and {DRIFT!r}")
    if formula.regions() - regions:
        raise ScenarioError(f"task names region {sorted(formula.regions() - regions)[0]!r}; a station task can only "
                            f"name the regions {GOAL!r} and {REST!r}")
    check_horizon(formula, station.tf_s, example=f"{station.reach_task!r}")
    try:
        steps = horizon_steps(formula, station.control_period_s)
    except STLError as exc:
        raise ScenarioError(f"task: {exc}") from None
    if steps < 1:
        raise ScenarioError(f"task horizon {formula.horizon_s:g} s is shorter than one control period "
                            f"({station.control_period_s:g} s): the episode would have no step")
    station.region_map()  # the goal box and the rest region as the task's regions (their own checks)
