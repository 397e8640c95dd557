"""A scenario's bodies, walls, obstacles and contact list as the plain numbers the batched kernels read.

Every env of a batch holds the same scenario, so everything here is a Python float or int: the kernels use
them as constants (torch.compile folds them into the generated code), and only the state is a tensor.

Contacts are listed once, in the fixed order in which the impulse solver visits them (see
:mod:`impact_env.transport.batched.physics`): every pair of bodies (i < j, scenario body order: robots, then
objects), then the four walls (bottom, top, left, right: the pymunk world's order of its wall boxes), then
the obstacles in the scenario's order, each static shape against every body at once.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from impact_env.geometry import ConvexPolygon
from impact_env.transport.scenario import Scenario

# the pymunk world's contact constants (impact_env.transport.physics), so that both resolve a contact alike
COLLISION_SLOP_M = 1e-4  # World sets space.collision_slop to this
COLLISION_BIAS = (1.0 - 0.1) ** 60  # chipmunk's default: 10 % of the overlap left after 1/60 s
WALLS = ("bottom", "top", "left", "right")


@dataclass(frozen=True)
class BoxShape:
    """An axis-aligned box obstacle [x0, x1] x [y0, y1] (m): its closest point is a clamp (closed form)."""

    name: str
    x0: float
    x1: float
    y0: float
    y1: float


@dataclass(frozen=True)
class PolygonShape:
    """Any other convex obstacle: counter-clockwise vertices, outward unit edge normals and their offsets
    (n . x <= offset inside), as :class:`~impact_env.geometry.ConvexPolygon` holds them (m)."""

    name: str
    vertices: tuple[tuple[float, float], ...]
    normals: tuple[tuple[float, float], ...]
    offsets: tuple[float, ...]


def obstacle_shape(name: str, polygon: ConvexPolygon) -> BoxShape | PolygonShape:
    """The kernel's description of an obstacle: a box when the polygon is an axis-aligned box."""
    box = polygon._box
    if box is not None:
        return BoxShape(name, *box)
    return PolygonShape(name, tuple(map(tuple, polygon.vertices.tolist())), tuple(map(tuple, polygon.normals.tolist())),
                        tuple(polygon.offsets.tolist()))


@dataclass(frozen=True)
class Scene:
    """The constants of one scenario for the batched world (SI units; per-body tuples in scenario order).

    ``restitution`` is the pair restitution the pymunk world simulates: each shape there has elasticity
    sqrt(e) and chipmunk multiplies the two, so the same product is used here (it differs from e in the last
    bit for some e).
    """

    names: tuple[str, ...]
    n_robots: int
    mass_kg: tuple[float, ...]
    inv_mass: tuple[float, ...]  # 1 / m, as chipmunk stores it
    inv_inertia: tuple[float, ...]
    radius_m: tuple[float, ...]
    wrench_limits: tuple[tuple[float, float, float], ...]  # per robot: Fx (N), Fy (N), torque (N m)
    world_box: tuple[float, float, float, float]
    obstacles: tuple[BoxShape | PolygonShape, ...]
    pairs: tuple[tuple[int, int], ...]  # body pairs (i < j)
    robot_object_pairs: tuple[tuple[int, int], ...]  # (index into pairs, object body index)
    restitution: float
    dt_s: float  # physics substep
    substeps: int
    bias_coef: float  # share of the overlap (beyond the slop) removed per substep, chipmunk's 1 - bias**dt
    slop_m: float
    position_m: tuple[tuple[float, float], ...]  # initial state
    velocity_mps: tuple[tuple[float, float], ...]
    heading_rad: tuple[float, ...]
    angular_velocity_radps: tuple[float, ...]

    @property
    def n_bodies(self) -> int:
        return len(self.names)

    @property
    def n_static(self) -> int:
        """Static shapes: the four walls and the obstacles."""
        return len(WALLS) + len(self.obstacles)

    @property
    def static_names(self) -> tuple[str, ...]:
        return tuple(f"wall_{w}" for w in WALLS) + tuple(o.name for o in self.obstacles)


def build_scene(scenario: Scenario, restitution: float | None = None) -> Scene:
    """The Scene of ``scenario``, simulated with ``restitution`` (default: the scenario's)."""
    bodies = scenario.bodies
    e = scenario.restitution if restitution is None else float(restitution)
    n_robots = len(scenario.robots)
    pairs = tuple((i, j) for i in range(len(bodies)) for j in range(i + 1, len(bodies)))
    ro_pairs = []
    for p, (i, j) in enumerate(pairs):
        if i < n_robots <= j:  # robots come first, so a robot-object pair has the robot as i
            ro_pairs.append((p, j))
    dt = scenario.physics_dt_s
    return Scene(
        names=tuple(b.name for b in bodies), n_robots=n_robots,
        mass_kg=tuple(b.mass_kg for b in bodies), inv_mass=tuple(1.0 / b.mass_kg for b in bodies),
        inv_inertia=tuple(1.0 / b.inertia_kgm2 for b in bodies), radius_m=tuple(b.radius_m for b in bodies),
        wrench_limits=tuple(r.wrench_limits for r in scenario.robots),
        world_box=scenario.world_box,
        obstacles=tuple(obstacle_shape(o.name, o.polygon) for o in scenario.obstacles),
        pairs=pairs, robot_object_pairs=tuple(ro_pairs),
        restitution=math.sqrt(e) * math.sqrt(e), dt_s=dt, substeps=scenario.substeps,
        bias_coef=1.0 - COLLISION_BIAS ** dt, slop_m=COLLISION_SLOP_M,
        position_m=tuple(b.position_m for b in bodies), velocity_mps=tuple(b.velocity_mps for b in bodies),
        heading_rad=tuple(b.heading_rad for b in bodies),
        angular_velocity_radps=tuple(b.angular_velocity_radps for b in bodies),
    )


def pair_arrays(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Index arrays (i, j) of the body pairs, for vectorised detection."""
    if not scene.pairs:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    i, j = zip(*scene.pairs)
    return np.array(i, dtype=np.int64), np.array(j, dtype=np.int64)
