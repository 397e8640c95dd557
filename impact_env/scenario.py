"""Scenario: the world, its bodies, the restitution and the STL task, loaded from a validated TOML file.

A scenario is the single description that the simulator, the planners and the plotters read. Shipped
scenarios live in ``impact_env/scenarios/*.toml``; a user file has the same format (see
``docs/scenario_format.md``). Every field is checked on load; unknown keys are errors, not ignored, and
every error names the field path, e.g. ``ScenarioError("robots[1].radius_m must be > 0, got -0.2")``.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from impact_env import limits
from impact_env.errors import ScenarioError, STLError
from impact_env.geometry import ConvexPolygon

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

_SCENARIO_PACKAGE = "impact_env.scenarios"
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
    source: str = ""
    _formula: Any = field(default=None, init=False, repr=False, compare=False, hash=False)

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
    files = resources.files(_SCENARIO_PACKAGE)
    return sorted(p.name[:-5] for p in files.iterdir() if p.name.endswith(".toml"))


def load_scenario(name_or_path: str | Path) -> Scenario:
    """Load a shipped scenario by name (``"corridor"``) or a TOML file by path, validated.

    Raises:
        ScenarioError: unknown name, unreadable file, text that is not UTF-8, invalid TOML or any invalid field.
    """
    if not isinstance(name_or_path, (str, Path)):
        raise ScenarioError("a scenario is a shipped name or a path to a .toml file, "
                            f"got {type(name_or_path).__name__}")
    text, source = _read_source(name_or_path)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{source}: not valid TOML: {exc}") from None
    except (ValueError, RecursionError) as exc:  # an integer of thousands of digits; arrays nested thousands deep
        raise ScenarioError(f"{source}: not a usable TOML file: {str(exc)[:120]}") from None
    return scenario_from_dict(data, source=source)


def _read_source(name_or_path: str | Path) -> tuple[str, str]:
    path = Path(name_or_path)
    try:
        is_path = path.suffix == ".toml" or path.exists() or "/" in str(name_or_path)
    except (OSError, ValueError):  # e.g. a NUL byte or a name too long for the file system
        raise ScenarioError(f"{str(name_or_path)[:80]!r} is neither a shipped scenario nor a readable path") from None
    if is_path:
        if not path.is_file():
            raise ScenarioError(f"scenario file {str(path)!r} does not exist")
        try:
            raw = path.read_bytes()
        except OSError as exc:
            raise ScenarioError(f"cannot read scenario file {str(path)!r}: {exc.strerror or exc}") from None
        try:
            return raw.decode("utf-8"), str(path)
        except UnicodeDecodeError as exc:
            line = raw[:exc.start].count(b"\n") + 1
            raise ScenarioError(f"{path}: not UTF-8 text (byte 0x{raw[exc.start]:02x} at line {line}, byte offset "
                                f"{exc.start}); TOML files must be UTF-8") from None
    name = str(name_or_path)
    if name not in scenario_names():
        from impact_env.names import shipped_names, suggestion
        from impact_env.station import station_names

        if name in station_names():
            raise ScenarioError(f"{name!r} is a tether station, not an impact scenario: load it with "
                                "impact_env.station.load_station (or use a Tether env)")
        raise ScenarioError(f"unknown scenario {name!r}{suggestion(name, shipped_names())}; shipped scenarios: "
                            f"{', '.join(scenario_names())} (or pass a path to a .toml file)")
    return resources.files(_SCENARIO_PACKAGE).joinpath(f"{name}.toml").read_text(encoding="utf-8"), name


class _Fields:
    """Reads one TOML table, tracking which keys were consumed so that leftovers are reported."""

    def __init__(self, table: Any, path: str) -> None:
        if not isinstance(table, dict):
            raise ScenarioError(f"{path} must be a table, got {type(table).__name__}")
        self.table, self.path, self.used = table, path, set()

    def _at(self, key: str) -> str:
        return f"{self.path}.{key}" if self.path else key

    def get(self, key: str, default: Any = ..., kind: str = "any") -> Any:
        self.used.add(key)
        if key not in self.table:
            if default is ...:
                raise ScenarioError(f"{self._at(key)} is required")
            return default
        return _check(self.table[key], kind, self._at(key))

    def finish(self) -> None:
        extra = sorted(set(self.table) - self.used)
        if extra:
            raise ScenarioError(f"{self._at(extra[0])}: unknown key (allowed here: {', '.join(sorted(self.used))})")


def _check(value: Any, kind: str, where: str) -> Any:
    if kind == "any":
        return value
    if kind == "str":
        if not isinstance(value, str):
            raise ScenarioError(f"{where} must be a string, got {_short(value)}")
        return value
    if kind == "name":
        if not isinstance(value, str) or not value.isidentifier():
            raise ScenarioError(f"{where} must be a name made of letters, digits and _, got {_short(value)}")
        return value
    if kind == "int":
        if isinstance(value, bool) or not isinstance(value, int):
            raise ScenarioError(f"{where} must be an integer, got {_short(value)}")
        return value
    if kind == "float":
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not _finite(value):
            raise ScenarioError(f"{where} must be a finite number, got {_short(value)}")
        return float(value)
    if kind == "vec2":
        if not isinstance(value, list) or len(value) != 2:
            raise ScenarioError(f"{where} must be a list of 2 numbers [x, y], got {_short(value)}")
        return tuple(_check(v, "float", f"{where}[{i}]") for i, v in enumerate(value))
    if kind == "box":
        if not isinstance(value, list) or len(value) != 4:
            raise ScenarioError(f"{where} must be [xmin, xmax, ymin, ymax], got {_short(value)}")
        box = tuple(_check(v, "float", f"{where}[{i}]") for i, v in enumerate(value))
        if not (box[0] < box[1] and box[2] < box[3]):
            raise ScenarioError(f"{where} must have xmin < xmax and ymin < ymax, got {list(box)}")
        return box
    raise AssertionError(kind)  # programming error, not user input


def _finite(value: int | float) -> bool:
    try:
        return math.isfinite(value)
    except OverflowError:  # an integer too large for a float
        return False


def _short(value: Any) -> str:
    try:
        text = repr(value)
    except (ValueError, RecursionError):  # an integer of thousands of digits; a list nested thousands deep
        return f"a {type(value).__name__}"
    return text if len(text) <= 60 else text[:57] + "..."


def _positive(value: float, where: str, allow_zero: bool = False) -> float:
    if value < 0 or (value == 0 and not allow_zero):
        raise ScenarioError(f"{where} must be {'>= 0' if allow_zero else '> 0'}, got {value}")
    return value


def _region(table: Any, where: str) -> Region:
    f = _Fields(table, where)
    name = f.get("name", kind="name")
    box = f.get("box", None, kind="box")
    vertices = f.get("polygon", None)
    if (box is None) == (vertices is None):
        raise ScenarioError(f"{where} needs exactly one of 'box = [xmin, xmax, ymin, ymax]' "
                            "or 'polygon = [[x, y], ...]'")
    f.finish()
    if box is not None:
        return Region(name, ConvexPolygon.from_box(*box, where=f"{where}.box"))
    if not isinstance(vertices, list):
        raise ScenarioError(f"{where}.polygon must be a list of [x, y] vertices")
    pts = [_check(v, "vec2", f"{where}.polygon[{i}]") for i, v in enumerate(vertices)]
    return Region(name, ConvexPolygon.from_vertices(pts, where=f"{where}.polygon"))


def _body(table: Any, where: str, robot: bool) -> Body:
    f = _Fields(table, where)
    name = f.get("name", kind="name")
    mass = _positive(f.get("mass_kg", kind="float"), f"{where}.mass_kg")
    radius = _positive(f.get("radius_m", kind="float"), f"{where}.radius_m")
    inertia = _positive(f.get("inertia_kgm2", kind="float"), f"{where}.inertia_kgm2")
    vbound = f.get("velocity_bound_mps", None, kind="vec2")
    if vbound is not None:
        for i, v in enumerate(vbound):
            _positive(v, f"{where}.velocity_bound_mps[{i}]")
    thrust = torque = None
    if robot:
        thrust = f.get("thrust_limit_N", kind="vec2")
        for i, v in enumerate(thrust):
            _positive(v, f"{where}.thrust_limit_N[{i}]")
        torque = _positive(f.get("torque_limit_Nm", kind="float"), f"{where}.torque_limit_Nm")
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
    try:
        return _build(data, source)
    except ScenarioError as exc:
        if str(exc).startswith(source):
            raise
        raise ScenarioError(f"{source}: {exc}") from None


def _build(data: dict, source: str) -> Scenario:
    top = _Fields(data, "")
    name = top.get("name", kind="name")
    description = top.get("description", "", kind="str")
    restitution = top.get("restitution", kind="float")
    if not 0.0 <= restitution <= 1.0:
        raise ScenarioError(f"restitution must be in [0, 1], got {restitution}")
    tf = _positive(top.get("tf_s", kind="float"), "tf_s")
    period = _positive(top.get("control_period_s", 0.1, kind="float"), "control_period_s")
    substeps = top.get("substeps", 10, kind="int")
    if substeps < 1:
        raise ScenarioError(f"substeps must be >= 1, got {substeps}")
    limits.check_timing(tf, period, substeps)
    task = top.get("task", kind="str")

    world = _Fields(top.get("world"), "world")
    world_box = world.get("box", kind="box")
    world.finish()
    world_poly = ConvexPolygon.from_box(*world_box, where="world.box")

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

    planner = _Fields(top.get("planner", {}), "planner")
    segments = planner.get("bezier_segments", {})
    if not isinstance(segments, dict):
        raise ScenarioError("planner.bezier_segments must be a table like { R1 = 4, O1 = 6 }")
    intervals = planner.get("intervals", None, kind="int")
    if intervals is not None and not 2 <= intervals <= MAX_PLANNER_INTERVALS:
        raise ScenarioError(f"planner.intervals must be in 2..{MAX_PLANNER_INTERVALS}, got {intervals}")
    degree = planner.get("robot_degree", None, kind="int")
    if degree is not None and not MIN_ROBOT_DEGREE <= degree <= MAX_ROBOT_DEGREE:
        raise ScenarioError(f"planner.robot_degree must be in {MIN_ROBOT_DEGREE}..{MAX_ROBOT_DEGREE}, got {degree}")
    planner.finish()
    top.finish()

    names = [r.name for r in obstacles + regions]
    bodies = robots + objects
    _unique(names, "region/obstacle")
    _unique([b.name for b in bodies], "body")
    if set(names) & {b.name for b in bodies}:
        raise ScenarioError(f"names are shared by a body and a region: {sorted(set(names) & {b.name for b in bodies})}")
    for key, value in segments.items():
        where = f"planner.bezier_segments.{key}"
        if key not in {b.name for b in bodies}:
            raise ScenarioError(f"{where}: no body named {key!r}")
        if _check(value, "int", where) < 1:
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
        planner_robot_degree=degree, source=source,
    )
    _check_task(scenario)
    return scenario


def _unique(names: list[str], what: str) -> None:
    seen = set()
    for n in names:
        if n in seen:
            raise ScenarioError(f"{what} name {n!r} is used twice")
        seen.add(n)


def _check_task(scenario: Scenario) -> None:
    from impact_env.stl import horizon_steps

    try:
        formula = scenario.formula
    except STLError as exc:
        raise ScenarioError(f"task: {exc}") from None
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
    if formula.horizon_s <= 0:
        raise ScenarioError("task has no temporal operator, so the episode would have no steps; "
                            "wrap it, e.g. 'F[0,100] in(O1, goal)'")
    if formula.horizon_s > scenario.tf_s + 1e-9:
        raise ScenarioError(f"task horizon {formula.horizon_s} s exceeds tf_s = {scenario.tf_s} s")
    try:
        steps = horizon_steps(formula, scenario.control_period_s)
    except STLError as exc:  # an interval between two samples
        raise ScenarioError(f"task: {exc}") from None
    if steps < 1:
        raise ScenarioError(f"task horizon {formula.horizon_s:g} s is shorter than one control period "
                            f"({scenario.control_period_s:g} s), so the episode would have no steps; "
                            "lengthen the task's intervals or shorten control_period_s")
