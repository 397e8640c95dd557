"""Scenario: the world, its bodies, the restitution and the STL task, loaded from a validated TOML file.

A scenario is the single description that the simulator, the planners and the plotters read. Shipped
scenarios live in ``impact_env/transport/scenarios/*.toml``; a user file has the same format (see
``docs/scenario_format.md``). Every field is checked on load (:mod:`impact_env.toml_fields`); unknown keys
are errors, not ignored, and every error names the field path, e.g.
``ScenarioError("robots[1].radius_m must be > 0, got -0.2")``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from impact_env import catalogue, limits
from impact_env.errors import ScenarioError, STLError, brief
from impact_env.geometry import ConvexPolygon
from impact_env.toml_fields import (
    Fields,
    check,
    check_horizon,
    is_finite,
    load_toml,
    positive,
    read_header,
    read_source,
    task_formula,
    with_source,
)

# the private names 0.2 code imported from impact_env.transport.scenario (station.py did), kept for that path's release
_Fields, _check, _finite, _positive, _short = Fields, check, is_finite, positive, brief

_STATION_GIVEN = ("{name!r} is a tether station, not an impact scenario: load it with impact_env.load_station (or "
                  "use a Tether env)")
MAX_PLANNER_INTERVALS = 1000  # the MILP grows linearly with them; far beyond what solves in minutes
MIN_ROBOT_DEGREE, MAX_ROBOT_DEGREE = 2, 8


@dataclass(frozen=True)
class Region:
    """A named convex polygon. Obstacles are regions that are also solid in the simulation."""

    name: str
    polygon: ConvexPolygon


@dataclass(frozen=True)
class Body:
    """A rigid disc: a robot (actuated) or an object (passive). SI units, angles in rad."""

    name: str
    mass_kg: float
    radius_m: float
    inertia_kgm2: float
    position_m: tuple[float, float]
    velocity_mps: tuple[float, float] = (0.0, 0.0)
    heading_rad: float = 0.0
    angular_velocity_radps: float = 0.0
    final_position_m: tuple[float, float] | None = None
    final_velocity_mps: tuple[float, float] | None = None
    velocity_bound_mps: tuple[float, float] | None = None  # per axis, |v_x| <= [0], |v_y| <= [1]
    # robots only
    thrust_limit_N: tuple[float, float] | None = None  # per body axis
    torque_limit_Nm: float | None = None

    @property
    def is_robot(self) -> bool:
        return self.thrust_limit_N is not None

    @property
    def wrench_limits(self) -> tuple[float, float, float]:
        """A robot's limits: (Fx (N), Fy (N), torque (N m)); ScenarioError for an object, which has none."""
        if self.thrust_limit_N is None or self.torque_limit_Nm is None:
            raise ScenarioError(f"body {self.name!r} is an object: it has no thrust_limit_N or torque_limit_Nm")
        fx, fy = self.thrust_limit_N
        return fx, fy, self.torque_limit_Nm


@dataclass(frozen=True)
class FinalBox:
    """How far an object's final state may lie from its planned one (per-axis half-widths): the terminal
    condition of the impact-robust planner (``[final_box]`` in the scenario file)."""

    object: str
    position_m: tuple[float, float]
    velocity_mps: tuple[float, float]


@dataclass(frozen=True)
class Scenario:
    """Everything that defines one transport task. Build with :func:`load_scenario`.

    Frozen, hashable and picklable. The task is parsed once, on first use of :attr:`formula`, and the tree
    is kept (it is not part of equality, the hash or the repr: it follows from ``task``).
    """

    name: str
    description: str
    world_box: tuple[float, float, float, float]  # xmin, xmax, ymin, ymax (m)
    obstacles: tuple[Region, ...]
    regions: tuple[Region, ...]
    robots: tuple[Body, ...]
    objects: tuple[Body, ...]
    restitution: float
    tf_s: float
    task: str
    control_period_s: float = 0.1
    substeps: int = 10
    bezier_segments: dict[str, int] = field(default_factory=dict, hash=False)  # compared, not hashed (a dict)
    planner_intervals: int | None = None  # time-grid intervals of the offline planner
    planner_robot_degree: int | None = None  # degree of the robots' Bezier curves in the planner
    planner_copy_intervals: int | None = None  # impact-robust planner: intervals a robot's copies may differ
    final_boxes: tuple[FinalBox, ...] = ()  # [final_box]: per object, for the impact-robust planner
    source: str = ""
    _formula: Any = field(default=None, init=False, repr=False, compare=False, hash=False)

    def final_box(self, name: str) -> FinalBox | None:
        """The ``[final_box]`` entry of object ``name``, or None if the file gives none."""
        for box in self.final_boxes:
            if box.object == name:
                return box
        return None

    @property
    def bodies(self) -> tuple[Body, ...]:
        """Robots first, then objects: the order of every per-body array in the package."""
        return self.robots + self.objects

    @property
    def physics_dt_s(self) -> float:
        return self.control_period_s / self.substeps

    def region_map(self) -> dict[str, ConvexPolygon]:
        """Name -> polygon for every region and obstacle (both can appear in the task)."""
        return {r.name: r.polygon for r in self.regions + self.obstacles}

    def body(self, name: str) -> Body:
        for b in self.bodies:
            if b.name == name:
                return b
        raise ScenarioError(f"scenario {self.name!r} has no body {name!r}; bodies: {[b.name for b in self.bodies]}")

    @property
    def formula(self):
        """The task as an STL syntax tree (parsed on first use, then kept)."""
        if self._formula is None:
            from impact_env.stl import parse

            object.__setattr__(self, "_formula", parse(self.task))
        return self._formula


# ----------------------------------------------------------------------------------------------- loading


def scenario_names() -> list[str]:
    """Names of the scenarios shipped with the package."""
    return catalogue.names_of("scenario")


def load_scenario(name_or_path: str | Path) -> Scenario:
    """Load a shipped scenario by name (``"corridor"``) or a TOML file by path, validated.

    Raises:
        ScenarioError: unknown name, unreadable file, text that is not UTF-8, invalid TOML or any invalid field.
    """
    data, source = load_toml(name_or_path, "scenario", elsewhere={"station": _STATION_GIVEN})
    return scenario_from_dict(data, source=source)


def _read_source(name_or_path: str | Path) -> tuple[str, str]:
    """(text, source) of a scenario name or path (the name 0.2 code imported from ``impact_env.transport.scenario``)."""
    return read_source(name_or_path, "scenario", {"station": _STATION_GIVEN})


def _region(table: Any, where: str) -> Region:
    f = Fields(table, where)
    name = f.get("name", kind="name")
    box = f.get("box", None, kind="box")
    vertices = f.get("polygon", None)
    if (box is None) == (vertices is None):
        raise ScenarioError(f"{where} needs exactly one of 'box = [xmin, xmax, ymin, ymax]' "
                            "or 'polygon = [[x, y], ...]'")
    f.finish()
    if box is not None:
        # kind="box" checked four numbers: *box cannot reach where=
        return Region(name, ConvexPolygon.from_box(*box, where=f"{where}.box"))  # type: ignore[misc]
    if not isinstance(vertices, list):
        raise ScenarioError(f"{where}.polygon must be a list of [x, y] vertices")
    pts = [check(v, "vec2", f"{where}.polygon[{i}]") for i, v in enumerate(vertices)]
    return Region(name, ConvexPolygon.from_vertices(pts, where=f"{where}.polygon"))


def _body(table: Any, where: str, robot: bool) -> Body:
    f = Fields(table, where)
    name = f.get("name", kind="name")
    mass = positive(f.get("mass_kg", kind="float"), f"{where}.mass_kg")
    radius = positive(f.get("radius_m", kind="float"), f"{where}.radius_m")
    inertia = positive(f.get("inertia_kgm2", kind="float"), f"{where}.inertia_kgm2")
    vbound = f.get("velocity_bound_mps", None, kind="vec2")
    if vbound is not None:
        for i, v in enumerate(vbound):
            positive(v, f"{where}.velocity_bound_mps[{i}]")
    thrust = torque = None
    if robot:
        thrust = f.get("thrust_limit_N", kind="vec2")
        for i, v in enumerate(thrust):
            positive(v, f"{where}.thrust_limit_N[{i}]")
        torque = positive(f.get("torque_limit_Nm", kind="float"), f"{where}.torque_limit_Nm")
    body = Body(
        name=name, mass_kg=mass, radius_m=radius, inertia_kgm2=inertia,
        position_m=f.get("position_m", kind="vec2"),
        velocity_mps=f.get("velocity_mps", (0.0, 0.0), kind="vec2"),
        heading_rad=f.get("heading_rad", 0.0, kind="float"),
        angular_velocity_radps=f.get("angular_velocity_radps", 0.0, kind="float"),
        final_position_m=f.get("final_position_m", None, kind="vec2"),
        final_velocity_mps=f.get("final_velocity_mps", None, kind="vec2"),
        velocity_bound_mps=vbound, thrust_limit_N=thrust, torque_limit_Nm=torque,
    )
    f.finish()
    return body


def scenario_from_dict(data: dict, source: str = "<dict>") -> Scenario:
    """Validate a parsed TOML document and build the Scenario; see :func:`load_scenario`."""
    return with_source(_build, data, source)


def _build(data: dict, source: str) -> Scenario:
    top = Fields(data, "")
    header = read_header(top, default_period_s=0.1)
    name, description, restitution = header.name, header.description, header.restitution
    tf, period, substeps = header.tf_s, header.control_period_s, header.substeps
    limits.check_timing(tf, period, substeps)
    task = top.get("task", kind="str")

    world = Fields(top.get("world"), "world")
    world_box = world.get("box", kind="box")
    world.finish()
    world_poly = ConvexPolygon.from_box(*world_box, where="world.box")  # type: ignore[misc]  # as in _region

    def tables(key: str) -> list:
        value = top.get(key, [])
        if not isinstance(value, list):
            raise ScenarioError(f"{key} must be an array of tables ([[{key}]]), got {type(value).__name__}")
        return value

    obstacles = tuple(_region(t, f"obstacles[{i}]") for i, t in enumerate(tables("obstacles")))
    regions = tuple(_region(t, f"regions[{i}]") for i, t in enumerate(tables("regions")))
    robots = tuple(_body(t, f"robots[{i}]", robot=True) for i, t in enumerate(tables("robots")))
    objects = tuple(_body(t, f"objects[{i}]", robot=False) for i, t in enumerate(tables("objects")))
    if not robots:
        raise ScenarioError("a scenario needs at least one [[robots]] entry")

    planner = Fields(top.get("planner", {}), "planner")
    segments = planner.get("bezier_segments", {})
    if not isinstance(segments, dict):
        raise ScenarioError("planner.bezier_segments must be a table like { R1 = 4, O1 = 6 }")
    intervals = planner.get("intervals", None, kind="int")
    if intervals is not None and not 2 <= intervals <= MAX_PLANNER_INTERVALS:
        raise ScenarioError(f"planner.intervals must be in 2..{MAX_PLANNER_INTERVALS}, got {intervals}")
    degree = planner.get("robot_degree", None, kind="int")
    if degree is not None and not MIN_ROBOT_DEGREE <= degree <= MAX_ROBOT_DEGREE:
        raise ScenarioError(f"planner.robot_degree must be in {MIN_ROBOT_DEGREE}..{MAX_ROBOT_DEGREE}, got {degree}")
    copy_intervals = planner.get("copy_intervals", None, kind="int")
    if copy_intervals is not None and not 1 <= copy_intervals <= (intervals or 10) // 2:
        raise ScenarioError(f"planner.copy_intervals must be in 1..{(intervals or 10) // 2} (half the grid's "
                            f"intervals), got {copy_intervals}")
    planner.finish()
    final_table = Fields(top.get("final_box", {}), "final_box")
    final_boxes = tuple(_final_box(final_table.get(key), f"final_box.{key}", key)
                        for key in list(final_table.table))
    final_table.finish()
    top.finish()

    names = [r.name for r in obstacles + regions]
    bodies = robots + objects
    _unique(names, "region/obstacle")
    _unique([b.name for b in bodies], "body")
    if set(names) & {b.name for b in bodies}:
        raise ScenarioError(f"names are shared by a body and a region: {sorted(set(names) & {b.name for b in bodies})}")
    for box in final_boxes:
        if box.object not in {o.name for o in objects}:
            raise ScenarioError(f"final_box.{box.object}: no object named {box.object!r} (objects: "
                                f"{', '.join(o.name for o in objects) or 'none'}); a final box bounds an object's "
                                "final state")
    for key, value in segments.items():
        where = f"planner.bezier_segments.{key}"
        if key not in {b.name for b in bodies}:
            raise ScenarioError(f"{where}: no body named {key!r}")
        if check(value, "int", where) < 1:
            raise ScenarioError(f"{where} must be >= 1, got {value}")

    for i, b in enumerate(bodies):
        kind, j = ("robots", i) if i < len(robots) else ("objects", i - len(robots))
        for label, p in (("position_m", b.position_m), ("final_position_m", b.final_position_m)):
            if p is None:
                continue
            margin = world_poly.signed_distance_xy(*p)
            if margin < b.radius_m - 1e-9:
                raise ScenarioError(f"{kind}[{j}].{label} = {list(p)} puts the disc (radius {b.radius_m} m) outside "
                                    f"the world box {list(world_box)}")
            for obs in obstacles:
                if obs.polygon.signed_distance_xy(*p) > -b.radius_m + 1e-9:
                    raise ScenarioError(f"{kind}[{j}].{label} = {list(p)} overlaps obstacle {obs.name!r} "
                                        f"(disc radius {b.radius_m} m)")
    for i in range(len(bodies)):
        for j in range(i + 1, len(bodies)):
            a, c = bodies[i], bodies[j]
            if math.dist(a.position_m, c.position_m) < a.radius_m + c.radius_m:
                raise ScenarioError(f"initial discs of {a.name!r} and {c.name!r} overlap")
    kinds = [f"robots[{i}]" for i in range(len(robots))] + [f"objects[{i}]" for i in range(len(objects))]
    for b, where in zip(bodies, kinds):
        limits.check_body(b, where, tf)
    limits.check_tunnelling(bodies, kinds, restitution, world_box, period, substeps)

    scenario = Scenario(
        name=name, description=description, world_box=world_box, obstacles=obstacles, regions=regions,
        robots=robots, objects=objects, restitution=restitution, tf_s=tf, task=task,
        control_period_s=period, substeps=substeps, bezier_segments=dict(segments), planner_intervals=intervals,
        planner_robot_degree=degree, planner_copy_intervals=copy_intervals, final_boxes=final_boxes, source=source,
    )
    _check_task(scenario)
    return scenario


def _final_box(table: Any, where: str, name: str) -> FinalBox:
    """``{ position_m = 0.5, velocity_mps = 0.05 }``; each a number > 0 or a per-axis pair [x, y] of them."""
    f = Fields(table, where)
    halves = {}
    for key in ("position_m", "velocity_mps"):
        value = f.get(key)
        pair = check(value, "vec2", f"{where}.{key}") if isinstance(value, list) else (
            (check(value, "float", f"{where}.{key}"),) * 2)
        for i, v in enumerate(pair):
            if v <= 0:
                at = f"{where}.{key}" + (f"[{i}]" if isinstance(value, list) else "")
                raise ScenarioError(f"{at} must be > 0 (a half-width), got {v}")
        halves[key] = pair
    f.finish()
    return FinalBox(name, halves["position_m"], halves["velocity_mps"])


def _unique(names: list[str], what: str) -> None:
    seen = set()
    for n in names:
        if n in seen:
            raise ScenarioError(f"{what} name {n!r} is used twice")
        seen.add(n)


def _check_task(scenario: Scenario) -> None:
    from impact_env.stl import horizon_steps

    formula = task_formula(scenario)
    bodies = {b.name for b in scenario.bodies}
    regions = set(scenario.region_map())
    unknown_bodies = sorted(formula.bodies() - bodies)
    if unknown_bodies:
        raise ScenarioError(f"task names body {unknown_bodies[0]!r}, which is not in the scenario "
                            f"(bodies: {', '.join(sorted(bodies))})")
    unknown_regions = sorted(formula.regions() - regions)
    if unknown_regions:
        raise ScenarioError(f"task names region {unknown_regions[0]!r}, which is not in the scenario "
                            f"(regions and obstacles: {', '.join(sorted(regions))})")
    check_horizon(formula, scenario.tf_s, example="'F[0,100] in(O1, goal)'")
    try:
        steps = horizon_steps(formula, scenario.control_period_s)
    except STLError as exc:  # an interval between two samples
        raise ScenarioError(f"task: {exc}") from None
    if steps < 1:
        raise ScenarioError(f"task horizon {formula.horizon_s:g} s is shorter than one control period "
                            f"({scenario.control_period_s:g} s), so the episode would have no steps; "
                            "lengthen the task's intervals or shorten control_period_s")
