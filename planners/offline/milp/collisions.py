"""Separation constraints (paper Eq. 26): on a grid interval, the bounding boxes of two bodies' curves,
grown by the sum of their radii, must not overlap. All bodies share the time grid, so interval k of one
body is simultaneous with interval k of another.

- robot-robot: on every interval;
- robot-object: on every interval except the two next to an impact of that pair (the paper's "best
  effort" variant, which it dropped for complexity; here the impact knots are grid knots, so exempting the
  pre- and post-impact intervals is one big-M term). Without it a point-mass plan may park a robot where
  the object's disc will pass, and the discs collide at unplanned times.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

from impact_env.transport.scenario import Body
from planners.offline.milp.model import LinExpr, Model
from planners.offline.milp.trajectories import Grid, Point, RobotTrajectory


class Curve(Protocol):
    """What separation reads of a robot: its spec, its grid and its control points on interval k (a
    :class:`RobotTrajectory`, or the impact-robust planner's :class:`~planners.offline.milp.copies.RobotCopies`,
    whose points are every copy's)."""

    @property
    def spec(self) -> Body: ...

    @property
    def grid(self) -> Grid: ...

    def points(self, k: int) -> list[Point]: ...


def _bounding_box(model: Model, robot, k: int, box) -> tuple[LinExpr, ...]:
    xmin, xmax, ymin, ymax = box
    name = f"{robot.spec.name}.bbox[{k}]"
    lo_x, hi_x = model.add_var(xmin, xmax, name=name + ".lo_x"), model.add_var(xmin, xmax, name=name + ".hi_x")
    lo_y, hi_y = model.add_var(ymin, ymax, name=name + ".lo_y"), model.add_var(ymin, ymax, name=name + ".hi_y")
    for p in robot.points(k):
        model.add([lo_x <= p[0], p[0] <= hi_x, lo_y <= p[1], p[1] <= hi_y], group="robot separation")
    return lo_x, hi_x, lo_y, hi_y


class Separation:
    """Adds separation constraints; keeps one bounding box per (body, interval)."""

    def __init__(self, model: Model, world_box) -> None:
        self.model, self.world_box = model, world_box
        self._boxes: dict[tuple[str, int], tuple[LinExpr, ...]] = {}

    def box(self, body, k: int) -> tuple[LinExpr, ...]:
        key = (body.spec.name, k)
        if key not in self._boxes:
            self._boxes[key] = _bounding_box(self.model, body, k, self.world_box)
        return self._boxes[key]

    def separate(self, a, b, k: int, group: str, exempt: LinExpr | None = None) -> None:
        """Boxes of a and b on interval k apart by the sum of radii, unless ``exempt`` is 1."""
        width, height = self.world_box[1] - self.world_box[0], self.world_box[3] - self.world_box[2]
        gap = a.spec.radius_m + b.spec.radius_m
        alx, ahx, aly, ahy = self.box(a, k)
        blx, bhx, bly, bhy = self.box(b, k)
        sides = [self.model.add_binary(name=f"sep[{a.spec.name},{b.spec.name},{k},{s}]") for s in range(4)]
        self.model.add(sum(sides, LinExpr()) >= 1, group=group)
        m_x, m_y = width + gap, height + gap
        for (lhs, rhs, big), s in zip(((ahx, blx, m_x), (bhx, alx, m_x), (ahy, bly, m_y), (bhy, aly, m_y)), sides):
            relax = (1 - s) * big
            if exempt is not None:
                relax = relax + exempt * big
            self.model.add(lhs + gap <= rhs + relax, group=group)


def add_robot_separation(model: Model, robots: Sequence[Curve], world_box,
                         separation: Separation | None = None) -> Separation:
    separation = separation or Separation(model, world_box)
    n = robots[0].grid.intervals
    for i, a in enumerate(robots):
        for b in robots[i + 1:]:
            for k in range(n):
                separation.separate(a, b, k, "robot separation")
    return separation


def add_robot_object_separation(model: Model, robots: list[RobotTrajectory], objects, impacts, world_box,
                                separation: Separation | None = None) -> Separation:
    separation = separation or Separation(model, world_box)
    n = robots[0].grid.intervals
    for r in robots:
        for o in objects:
            for k in range(n):
                near = [impacts.z[(r.spec.name, o.spec.name, j)] for j in (k, k + 1)
                        if (r.spec.name, o.spec.name, j) in impacts.z]
                separation.separate(r, o, k, "robot-object separation", exempt=sum(near, LinExpr()) if near else None)
    return separation
