"""Robot-robot separation (paper Eq. 26): on every grid interval, the bounding boxes of two robots' curves,
grown by the sum of their radii, must not overlap. Robots share the time grid, so interval k of one robot
is simultaneous with interval k of the other. Robot-object contact is left to the controller, as in the
paper (impacts are wanted there)."""

from __future__ import annotations

from planners.milp.model import LinExpr, Model
from planners.milp.trajectories import RobotTrajectory


def _bounding_box(model: Model, robot: RobotTrajectory, k: int, box) -> tuple[LinExpr, ...]:
    xmin, xmax, ymin, ymax = box
    name = f"{robot.spec.name}.bbox[{k}]"
    lo_x, hi_x = model.add_var(xmin, xmax, name=name + ".lo_x"), model.add_var(xmin, xmax, name=name + ".hi_x")
    lo_y, hi_y = model.add_var(ymin, ymax, name=name + ".lo_y"), model.add_var(ymin, ymax, name=name + ".hi_y")
    for p in robot.points(k):
        model.add([lo_x <= p[0], p[0] <= hi_x, lo_y <= p[1], p[1] <= hi_y], group="robot separation")
    return lo_x, hi_x, lo_y, hi_y


def add_robot_separation(model: Model, robots: list[RobotTrajectory], world_box) -> None:
    if len(robots) < 2:
        return
    n = robots[0].grid.intervals
    boxes = {(r.spec.name, k): _bounding_box(model, r, k, world_box) for r in robots for k in range(n)}
    width, height = world_box[1] - world_box[0], world_box[3] - world_box[2]
    for i, a in enumerate(robots):
        for b in robots[i + 1:]:
            gap = a.spec.radius_m + b.spec.radius_m
            for k in range(n):
                alx, ahx, aly, ahy = boxes[(a.spec.name, k)]
                blx, bhx, bly, bhy = boxes[(b.spec.name, k)]
                sides = [model.add_binary(name=f"sep[{a.spec.name},{b.spec.name},{k},{s}]") for s in range(4)]
                model.add(sum(sides, LinExpr()) >= 1, group="robot separation")
                m_x, m_y = width + gap, height + gap
                for (lhs, rhs, big), s in zip(((ahx, blx, m_x), (bhx, alx, m_x), (ahy, bly, m_y), (bhy, aly, m_y)),
                                              sides):
                    model.add(lhs + gap <= rhs + (1 - s) * big, group="robot separation")
