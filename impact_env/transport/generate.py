"""Random impact-transport tasks in four families, each an ordinary scenario file: ``impact-env generate``.

    scenario = generate_task("obstacle_avoidance", seed=7)
    write_task("obstacle_avoidance", 7, "task.toml")    # the same file on every machine

Families (:data:`FAMILIES`; sizes and ranges in :data:`FAMILY_LIMITS` and ``docs/generated_tasks.md``):

- ``throw_and_catch``: random goals and starts on an open table; every object ends held in its goal;
- ``obstacle_avoidance``: one or two random convex obstacles (polygons of 3-6 vertices on an ellipse), the
  first between an object and its goal; no body may enter one;
- ``gaps``: a wall across the table with one or two gaps of random height and width (the corridor family);
  objects start on one side and end in goals on the other;
- ``timed_visits``: O1 visits one or two random regions, each within its own time window, and ends held in a
  third; a second object is held in a goal of its own.

Every task has 2-4 robots (the paper's freeflyer: 16.8 kg, 0.2 m, 2.8 N per axis, 0.3 m/s) and 1-2
objects, and is drawn from ``random.Random`` seeded with the family and seed, using only ``random()``,
whose stream Python keeps stable across versions; coordinates are on a 5 cm grid. So a seed gives the same
file everywhere. A draw that breaks a placement rule is redrawn from the same stream; the finished task is
written as TOML (:mod:`impact_env.transport.scenario_toml`), loaded back through the ordinary loader, and
checked by :func:`check_task` (bodies clear of each other, of walls and of obstacles; regions and
obstacles inside the world; goals clear of obstacles). Whether a task can be done is the planner's
question, not this module's (``impact-env filter``, in ``planners/``).
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass
from pathlib import Path

from shapely.geometry import Point, Polygon, box

from impact_env.errors import GeneratedTaskError
from impact_env.transport.scenario import Scenario
from impact_env.transport.scenario_toml import scenario_from_toml, scenario_to_toml

__all__ = ["FAMILIES", "FAMILY_LIMITS", "GENERATOR_VERSION", "FamilyLimits", "GeneratedTaskError", "check_family",
           "check_task", "generate_task", "generate_toml", "task_name", "write_task"]

GENERATOR_VERSION = 2  # bumped whenever a seed's file changes (2: timed visits' windows allow the first push)
FAMILIES = ("throw_and_catch", "obstacle_avoidance", "gaps", "timed_visits")
GRID_M = 0.05  # every drawn coordinate is a multiple of this
HOLD_S = 5.0  # every task ends with each object held in its last region for this long
CLEARANCE_M = 0.2  # free space between any two discs, a disc and a wall or obstacle, at the start and end
MAX_REDRAWS = 200
PACE_MPS = 0.15  # timed visits: windows open when an object at this speed could be there (bound 0.35 m/s)
FIRST_HIT_S = 8.0  # timed visits: time allowed before the first push (a robot must reach the object first)
MAX_TIMED_TF_S = 80.0

ROBOT = {"mass_kg": 16.8, "radius_m": 0.2, "inertia_kgm2": 0.1594, "velocity_bound_mps": (0.3, 0.3),
         "thrust_limit_N": (2.8, 2.8), "torque_limit_Nm": 0.2}
OBJECT = {"mass_kg": 16.8, "radius_m": 0.2, "inertia_kgm2": 0.1594, "velocity_bound_mps": (0.35, 0.35)}
RADIUS_M = 0.2


@dataclass(frozen=True)
class FamilyLimits:
    """The most of each thing a family's task has: the padding of a goal-conditioned observation."""

    robots: int
    objects: int
    regions: int  # regions the task names (goals, visits)
    obstacles: int
    obstacle_vertices: int  # per obstacle


FAMILY_LIMITS = {
    "throw_and_catch": FamilyLimits(robots=4, objects=2, regions=2, obstacles=0, obstacle_vertices=0),
    "obstacle_avoidance": FamilyLimits(robots=4, objects=2, regions=2, obstacles=2, obstacle_vertices=6),
    "gaps": FamilyLimits(robots=4, objects=2, regions=2, obstacles=3, obstacle_vertices=4),
    "timed_visits": FamilyLimits(robots=4, objects=2, regions=4, obstacles=0, obstacle_vertices=0),
}


_Redraw = GeneratedTaskError  # raised inside a draw when a placement rule fails: the task is drawn again


class _Draw:
    """The random stream of one task: uniform draws on a grid, from ``random.Random.random`` only."""

    def __init__(self, family: str, seed: int) -> None:
        self.rng = random.Random(f"impact_env.generate/{family}/{seed}")

    def unit(self) -> float:
        return self.rng.random()

    def integer(self, low: int, high: int) -> int:
        """Uniform on low..high (both included)."""
        return low + min(int(self.unit() * (high - low + 1)), high - low)

    def grid(self, low: float, high: float, step: float = GRID_M) -> float:
        """Uniform on the multiples of ``step`` in [low, high]."""
        k0, k1 = math.ceil(low / step - 1e-9), math.floor(high / step + 1e-9)
        if k1 < k0:
            raise _Redraw
        return round(self.integer(k0, k1) * step, 6)


# ------------------------------------------------------------------------------------------ placement


class _Layout:
    """What has been placed so far (world, discs, solid shapes, regions), and where a new thing may go."""

    def __init__(self, width: float, height: float) -> None:
        self.width, self.height = width, height
        self.discs: list[tuple[float, float]] = []
        self.solids: list[Polygon] = []
        self.regions: list[Polygon] = []

    def free_point(self, draw: _Draw, x_range: tuple[float, float] | None = None, away_from_regions: bool = True,
                   far_from: tuple[tuple[float, float], float] | None = None) -> tuple[float, float]:
        """A disc centre with :data:`CLEARANCE_M` to the world's walls, to solids and to the other discs."""
        margin = RADIUS_M + CLEARANCE_M
        lo, hi = x_range or (margin, self.width - margin)
        for _ in range(MAX_REDRAWS):
            p = (draw.grid(max(lo, margin), min(hi, self.width - margin)),
                 draw.grid(margin, self.height - margin))
            if self.disc_fits(p, away_from_regions) and (
                    far_from is None or math.dist(p, far_from[0]) >= far_from[1]):
                self.discs.append(p)
                return p
        raise _Redraw

    def disc_fits(self, p: tuple[float, float], away_from_regions: bool = True) -> bool:
        disc = Point(p).buffer(RADIUS_M + CLEARANCE_M, 16)
        if any(math.dist(p, q) < 2 * RADIUS_M + CLEARANCE_M for q in self.discs):
            return False
        if any(s.intersects(disc) for s in self.solids):
            return False
        return not (away_from_regions and any(r.intersects(Point(p).buffer(RADIUS_M, 16)) for r in self.regions))

    def free_box(self, draw: _Draw, side: float, x_range: tuple[float, float] | None = None,
                 far_from: tuple[tuple[float, float], float] | None = None) -> tuple[float, float, float, float]:
        """An axis-aligned square region of ``side`` inside the world, clear of solids, discs and regions."""
        half = side / 2
        lo, hi = x_range or (CLEARANCE_M + half, self.width - CLEARANCE_M - half)
        for _ in range(MAX_REDRAWS):
            cx = draw.grid(max(lo, CLEARANCE_M + half), min(hi, self.width - CLEARANCE_M - half))
            cy = draw.grid(CLEARANCE_M + half, self.height - CLEARANCE_M - half)
            b = (round(cx - half, 6), round(cx + half, 6), round(cy - half, 6), round(cy + half, 6))
            shape = box(b[0], b[2], b[1], b[3])
            if far_from is not None and math.dist((cx, cy), far_from[0]) < far_from[1]:
                continue
            if any(s.distance(shape) < CLEARANCE_M for s in self.solids + self.regions):
                continue
            if any(shape.distance(Point(q)) < RADIUS_M for q in self.discs):
                continue
            self.regions.append(shape)
            return b
        raise _Redraw


def _body(name: str, position: tuple[float, float], robot: bool) -> dict:
    table = {"name": name, **(ROBOT if robot else OBJECT), "position_m": list(position),
             "final_velocity_mps": [0.0, 0.0]}
    if robot:
        table["final_position_m"] = list(position)  # every robot returns to where it started, at rest
    return {k: list(v) if isinstance(v, tuple) else v for k, v in table.items()}


def _window(a: float, b: float) -> str:
    return f"[{a:g},{b:g}]"


def _holds(goals: list[tuple[str, str]], tf: float) -> list[str]:
    return [f"G{_window(tf - HOLD_S, tf)} in({obj}, {goal})" for obj, goal in goals]


def _robots(draw: _Draw, layout: _Layout, n: int, sides: list[tuple[float, float]] | None = None) -> list[dict]:
    """``n`` robots; with ``sides``, robot k starts within x range ``sides[k]`` (the rest anywhere)."""
    sides = sides or []
    return [_body(f"R{k + 1}", layout.free_point(draw, sides[k] if k < len(sides) else None), robot=True)
            for k in range(n)]


# ------------------------------------------------------------------------------------------ families


def _throw_and_catch(draw: _Draw) -> dict:
    width, height = draw.grid(4.0, 7.0, 0.5), draw.grid(3.0, 5.0, 0.5)
    n_robots, n_objects = draw.integer(2, 4), draw.integer(1, 2)
    tf = draw.grid(30.0, 50.0, 5.0)
    layout = _Layout(width, height)
    goals, objects = [], []
    for _ in range(n_objects):
        goals.append(layout.free_box(draw, draw.grid(0.8, 1.2, 0.1)))
    for i, g in enumerate(goals):
        centre = ((g[0] + g[1]) / 2, (g[2] + g[3]) / 2)
        objects.append(_body(f"O{i + 1}", layout.free_point(draw, far_from=(centre, 1.5)), robot=False))
    return {"world": (width, height), "tf_s": tf, "regions": [(f"goal{i + 1}", g) for i, g in enumerate(goals)],
            "obstacles": [], "objects": objects, "robots": _robots(draw, layout, n_robots),
            "task": _holds([(f"O{i + 1}", f"goal{i + 1}") for i in range(n_objects)], tf),
            "description": f"{n_robots} robots take {n_objects} object(s) into their goals and hold them there."}


def _convex_polygon(draw: _Draw, centre: tuple[float, float]) -> list[list[float]]:
    """3-6 vertices on a random ellipse (semi-axes 0.5-1.0 m) around ``centre``: always convex."""
    k = draw.integer(3, 6)
    a, b, turn = draw.grid(0.5, 1.0), draw.grid(0.5, 1.0), 2 * math.pi * draw.unit()
    angles = [2 * math.pi * (i + 0.5 * draw.unit()) / k for i in range(k)]
    points = []
    for t in angles:
        x, y = a * math.cos(t), b * math.sin(t)
        points.append([round(centre[0] + x * math.cos(turn) - y * math.sin(turn), 2),
                       round(centre[1] + x * math.sin(turn) + y * math.cos(turn), 2)])
    return points


def _obstacle_avoidance(draw: _Draw) -> dict:
    width, height = draw.grid(6.0, 9.0, 0.5), draw.grid(5.0, 7.0, 0.5)
    n_robots, n_objects, n_obstacles = draw.integer(2, 4), draw.integer(1, 2), draw.integer(1, 2)
    tf = draw.grid(40.0, 60.0, 5.0)
    layout = _Layout(width, height)
    centre = (draw.grid(1.5, width - 1.5), draw.grid(1.5, height - 1.5))
    first = _convex_polygon(draw, centre)
    layout.solids.append(Polygon(first))
    # the first object starts on one side of the first obstacle and has its goal on the other
    angle = 2 * math.pi * draw.unit()
    u, n = (math.cos(angle), math.sin(angle)), (-math.sin(angle), math.cos(angle))
    reach = 1.0 + draw.grid(0.5, 1.5)
    side = draw.grid(-0.5, 0.5)
    start = (round((centre[0] - reach * u[0] + side * n[0]) / GRID_M) * GRID_M,
             round((centre[1] - reach * u[1] + side * n[1]) / GRID_M) * GRID_M)
    start = (round(start[0], 6), round(start[1], 6))
    margin = RADIUS_M + CLEARANCE_M
    if not (margin <= start[0] <= width - margin and margin <= start[1] <= height - margin
            and layout.disc_fits(start)):
        raise _Redraw
    layout.discs.append(start)
    goal_side = draw.grid(0.8, 1.1, 0.1)
    far = (centre[0] + reach * u[0], centre[1] + reach * u[1])
    goals = [_box_near(draw, layout, far, goal_side)]
    obstacles = [first]
    for _ in range(n_obstacles - 1):
        c = (draw.grid(1.2, width - 1.2), draw.grid(1.2, height - 1.2))
        poly = _convex_polygon(draw, c)
        shape = Polygon(poly)
        if any(s.distance(shape) < 2 * margin for s in layout.solids) or any(
                r.distance(shape) < CLEARANCE_M for r in layout.regions) or any(
                shape.distance(Point(q)) < margin for q in layout.discs):
            raise _Redraw
        layout.solids.append(shape)
        obstacles.append(poly)
    objects = [_body("O1", start, robot=False)]
    for i in range(1, n_objects):
        g = layout.free_box(draw, draw.grid(0.8, 1.1, 0.1))
        goals.append(g)
        objects.append(_body(f"O{i + 1}", layout.free_point(draw, far_from=(((g[0] + g[1]) / 2, (g[2] + g[3]) / 2),
                                                                             1.5)), robot=False))
    robots = _robots(draw, layout, n_robots)
    names = [r["name"] for r in robots] + [o["name"] for o in objects]
    avoid = " & ".join(f"!in({b}, obs{j + 1})" for b in names for j in range(len(obstacles)))
    return {"world": (width, height), "tf_s": tf, "regions": [(f"goal{i + 1}", g) for i, g in enumerate(goals)],
            "obstacles": [(f"obs{j + 1}", p) for j, p in enumerate(obstacles)], "objects": objects,
            "robots": robots,
            "task": _holds([(f"O{i + 1}", f"goal{i + 1}") for i in range(n_objects)], tf) + [
                f"G{_window(0, tf)} ({avoid})"],
            "description": f"{n_robots} robots take {n_objects} object(s) round {len(obstacles)} convex obstacle(s) "
                           "into their goals."}


def _box_near(draw: _Draw, layout: _Layout, centre: tuple[float, float], side: float) -> tuple[float, ...]:
    """A square region of ``side`` centred on the grid point nearest ``centre``, if it is free."""
    half = side / 2
    cx, cy = round(round(centre[0] / GRID_M) * GRID_M, 6), round(round(centre[1] / GRID_M) * GRID_M, 6)
    if not (CLEARANCE_M + half <= cx <= layout.width - CLEARANCE_M - half
            and CLEARANCE_M + half <= cy <= layout.height - CLEARANCE_M - half):
        raise _Redraw
    b = (round(cx - half, 6), round(cx + half, 6), round(cy - half, 6), round(cy + half, 6))
    shape = box(b[0], b[2], b[1], b[3])
    if any(s.distance(shape) < CLEARANCE_M for s in layout.solids + layout.regions) or any(
            shape.distance(Point(q)) < RADIUS_M for q in layout.discs):
        raise _Redraw
    layout.regions.append(shape)
    return b


def _gaps(draw: _Draw) -> dict:
    width, height = draw.grid(6.0, 8.0, 0.5), draw.grid(3.5, 5.0, 0.5)
    n_robots, n_objects, n_gaps = draw.integer(2, 4), draw.integer(1, 2), draw.integer(1, 2)
    tf = draw.grid(40.0, 60.0, 5.0)
    x0 = draw.grid(0.4 * width, 0.6 * width)
    x1 = round(x0 + draw.grid(0.3, 0.6), 6)
    # gaps: widths 0.8-1.2 m, each at least 0.3 m from the world's edge and 0.6 m of wall between two
    widths = [draw.grid(0.8, 1.2) for _ in range(n_gaps)]
    spare = height - 2 * 0.3 - sum(widths) - 0.6 * (n_gaps - 1)
    if spare < 0:
        raise _Redraw
    cuts = sorted(draw.grid(0.0, spare) for _ in range(n_gaps))
    gaps, y = [], 0.3
    for k, (w, c) in enumerate(zip(widths, cuts)):
        lo = round(y + c - (cuts[k - 1] if k else 0.0), 6)
        gaps.append((lo, round(lo + w, 6)))
        y = lo + w + 0.6
    edges = [0.0] + [v for g in gaps for v in g] + [height]
    walls = [(round(edges[2 * i], 6), round(edges[2 * i + 1], 6)) for i in range(n_gaps + 1)]
    walls = [(a, b) for a, b in walls if b - a >= GRID_M]
    layout = _Layout(width, height)
    for a, b in walls:
        layout.solids.append(box(x0, a, x1, b))
    left, right = (RADIUS_M + CLEARANCE_M, x0 - 0.6), (x1 + 0.6, width - RADIUS_M - CLEARANCE_M)
    goals = [layout.free_box(draw, draw.grid(0.8, 1.1, 0.1), x_range=(right[0] + 0.5, right[1]))
             for _ in range(n_objects)]
    objects = [_body(f"O{i + 1}", layout.free_point(draw, x_range=(left[0] + 0.4, left[1])), robot=False)
               for i in range(n_objects)]
    sides = [left, right] + [left if draw.unit() < 0.5 else right for _ in range(n_robots - 2)]
    robots = _robots(draw, layout, n_robots, sides)
    return {"world": (width, height), "tf_s": tf, "regions": [(f"goal{i + 1}", g) for i, g in enumerate(goals)],
            "obstacles": [(f"wall{k + 1}", (x0, x1, a, b)) for k, (a, b) in enumerate(walls)],
            "objects": objects, "robots": robots,
            "task": _holds([(f"O{i + 1}", f"goal{i + 1}") for i in range(n_objects)], tf),
            "description": f"{n_robots} robots take {n_objects} object(s) through a wall with {n_gaps} gap(s) "
                           "into their goals."}


def _timed_visits(draw: _Draw) -> dict:
    width, height = draw.grid(5.0, 7.0, 0.5), draw.grid(4.0, 6.0, 0.5)
    n_robots, n_objects = draw.integer(2, 4), draw.integer(1, 2)
    layout = _Layout(width, height)
    starts = [layout.free_point(draw) for _ in range(n_objects)]
    regions, windows = [], []
    # O1 visits 1 or 2 regions, each within its window, and is held in a third; O2 (if any) is held in a goal
    t, pos = FIRST_HIT_S, starts[0]
    n = draw.integer(2, 3)
    for k in range(n):
        name = f"V{chr(ord('A') + k)}"
        b = layout.free_box(draw, draw.grid(1.0, 1.2, 0.1), far_from=(pos, 1.2))
        centre = ((b[0] + b[1]) / 2, (b[2] + b[3]) / 2)
        t = float(math.ceil(t + math.dist(pos, centre) / PACE_MPS))  # earliest arrival at the visit pace
        regions.append((name, b))
        if k < n - 1:
            windows.append(("O1", name, t, t + draw.grid(12.0, 16.0, 1.0)))
        pos = centre
    tf = max(t + draw.grid(6.0, 10.0, 1.0), max(w[3] for w in windows))
    holds = [("O1", regions[-1][0])]
    if n_objects == 2:
        regions.append(("goal2", layout.free_box(draw, draw.grid(1.0, 1.2, 0.1), far_from=(starts[1], 1.5))))
        holds.append(("O2", "goal2"))
    if tf > MAX_TIMED_TF_S:
        raise _Redraw
    clauses = [f"F{_window(a, b)} in({obj}, {name})" for obj, name, a, b in windows] + _holds(holds, tf)
    objects = [_body(f"O{i + 1}", p, robot=False) for i, p in enumerate(starts)]
    return {"world": (width, height), "tf_s": tf, "regions": regions, "obstacles": [], "objects": objects,
            "robots": _robots(draw, layout, n_robots), "task": clauses,
            "description": f"{n_robots} robots: O1 visits {n - 1} region(s), each within its window, and is held in "
                           f"a last one{'; O2 is held in its goal' if n_objects == 2 else ''}."}


_FAMILY_DRAWS = {"throw_and_catch": _throw_and_catch, "obstacle_avoidance": _obstacle_avoidance, "gaps": _gaps,
                 "timed_visits": _timed_visits}


# ------------------------------------------------------------------------------------------ public API


def task_name(family: str, seed: int) -> str:
    """The scenario name of a generated task: ``<family>_<seed>``."""
    return f"{family}_{seed}"


def check_family(family: str, seed: int) -> None:
    """A known family and a seed in [0, 2**63), else :class:`GeneratedTaskError`."""
    if family not in FAMILIES:
        from impact_env import catalogue

        raise GeneratedTaskError(f"unknown task family {family!r}{catalogue.suggestion(family, list(FAMILIES))}; "
                                 f"families: {', '.join(FAMILIES)}")
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2**63:
        raise GeneratedTaskError(f"seed must be an integer in [0, 2**63), got {seed!r}")


def _document(family: str, seed: int) -> dict:
    draw = _Draw(family, seed)
    for _ in range(MAX_REDRAWS):
        try:
            spec = _FAMILY_DRAWS[family](draw)
        except _Redraw:
            continue
        restitution = draw.grid(0.6, 0.85)
        width, height = spec["world"]
        doc = {"name": task_name(family, seed), "description": spec["description"], "restitution": restitution,
               "tf_s": float(spec["tf_s"]), "control_period_s": 0.1, "substeps": 10,
               "task": " & ".join(spec["task"]), "world": {"box": [0.0, float(width), 0.0, float(height)]},
               "obstacles": [_region_table(n, r) for n, r in spec["obstacles"]],
               "regions": [_region_table(n, r) for n, r in spec["regions"]],
               "robots": spec["robots"], "objects": spec["objects"],
               "planner": {"intervals": 12 if family == "timed_visits" else 10, "robot_degree": 4}}
        return doc
    raise GeneratedTaskError(f"no {family} task satisfied the placement rules in {MAX_REDRAWS} draws of seed {seed}")


def _region_table(name: str, shape) -> dict:
    if len(shape) == 4 and not isinstance(shape[0], list):
        return {"name": name, "box": [float(v) for v in shape]}
    return {"name": name, "polygon": [[float(x), float(y)] for x, y in shape]}


def generate_toml(family: str, seed: int) -> str:
    """The scenario file (TOML text) of task ``seed`` of ``family``; checked (see :func:`check_task`).

    Raises:
        GeneratedTaskError: an unknown family, a bad seed, or (a bug) a task that fails its checks.
    """
    from impact_env.transport.scenario import scenario_from_dict

    check_family(family, seed)
    scenario = scenario_from_dict(_document(family, seed), source=task_name(family, seed))
    check_task(scenario)
    comment = (f"Generated by impact_env.transport.generate (version {GENERATOR_VERSION}): "
               f"impact-env generate --family {family} --seed {seed}")
    text = scenario_to_toml(scenario, comment=comment)
    if scenario_from_toml(text, source=scenario.name) != scenario:  # the writer's promise, kept on every task
        raise GeneratedTaskError(f"{scenario.name}: the written file does not read back to the same scenario")
    return text


def generate_task(family: str, seed: int) -> Scenario:
    """Task ``seed`` of ``family`` as a :class:`Scenario` (loaded from the text :func:`generate_toml` writes)."""
    return scenario_from_toml(generate_toml(family, seed), source=task_name(family, seed))


def write_task(family: str, seed: int, path: str | Path) -> Path:
    """Write task ``seed`` of ``family`` to ``path`` (a ``.toml`` file; its folder is created), atomically."""
    from impact_env.results_store import write_atomic

    return write_atomic(path, generate_toml(family, seed))  # its folder created, never half a file


def check_task(scenario: Scenario) -> None:
    """The rules every generated task keeps, beyond what the loader checks.

    Every region and obstacle inside the world box; every disc at its start and (for robots) its final
    position inside the world, clear of every obstacle and of every other disc by :data:`CLEARANCE_M`
    (less 1 mm for the 5 cm grid's rounding); every region clear of every obstacle.

    Raises:
        GeneratedTaskError: naming the body or region and the rule.
    """
    xmin, xmax, ymin, ymax = scenario.world_box
    world = box(xmin, ymin, xmax, ymax)
    tol = 1e-3
    shapes = {}
    for region in scenario.regions + scenario.obstacles:
        shape = Polygon([tuple(v) for v in region.polygon.vertices])
        if not world.buffer(1e-9).contains(shape):
            raise GeneratedTaskError(f"{scenario.name}: region {region.name!r} reaches outside the world box "
                                     f"{list(scenario.world_box)}")
        shapes[region.name] = shape
    for region in scenario.regions:
        for obstacle in scenario.obstacles:
            if shapes[region.name].intersects(shapes[obstacle.name]):
                raise GeneratedTaskError(f"{scenario.name}: region {region.name!r} overlaps obstacle "
                                         f"{obstacle.name!r}")
    placed = [(b, b.position_m, "start") for b in scenario.bodies]
    placed += [(b, b.final_position_m, "final position") for b in scenario.robots if b.final_position_m is not None]
    for body, p, what in placed:
        if min(p[0] - xmin, xmax - p[0], p[1] - ymin, ymax - p[1]) < body.radius_m + CLEARANCE_M - tol:
            raise GeneratedTaskError(f"{scenario.name}: {body.name}'s {what} {list(p)} is within "
                                     f"{CLEARANCE_M} m of the world's edge")
        for obstacle in scenario.obstacles:
            if shapes[obstacle.name].distance(Point(p)) < body.radius_m + CLEARANCE_M - tol:
                raise GeneratedTaskError(f"{scenario.name}: {body.name}'s {what} {list(p)} is within "
                                         f"{CLEARANCE_M} m of obstacle {obstacle.name!r}")
    for kind in ("start", "final position"):
        points = [(b, p) for b, p, what in placed if what == kind or (kind == "final position" and what == "start"
                                                                      and not b.is_robot)]
        for i in range(len(points)):
            for j in range(i + 1, len(points)):
                (a, p), (c, q) = points[i], points[j]
                if math.dist(p, q) < a.radius_m + c.radius_m + CLEARANCE_M - tol:
                    raise GeneratedTaskError(f"{scenario.name}: the discs of {a.name} and {c.name} are closer than "
                                             f"{CLEARANCE_M} m ({kind})")
