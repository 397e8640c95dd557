"""Decision variables of the bodies' trajectories on the planner's time grid, and their kinematics.

The planner uses ONE time grid for all bodies: N intervals of equal duration dt = tf / N, knots t_k = k dt.
On interval k a robot is a degree-d Bezier curve (control points are variables) and an object a straight
segment between its knot positions. On a fixed grid every kinematic condition is linear and EXACT:

- velocity   dr/dt = r'(s) / dt          -> |d (r^(i+1) - r^(i))| <= v_max dt            (Eq. 25)
- accel.     d2r/dt2 = r''(s) / dt^2      -> |d (d-1) (r^(i+2) - 2 r^(i+1) + r^(i))| <= a_max dt^2

so plans respect the robots' thrust limits, which the paper's variable time curves cannot bound linearly.
Impacts happen at knots; the grid resolution is a planner option. Why one fixed grid:
``docs/planner_design.md#time-grid-and-trajectories``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from impact_env.transport.scenario import Body, Scenario
from planners.offline.milp.model import LinExpr, Model

Point = tuple[LinExpr, LinExpr]


@dataclass(frozen=True)
class Grid:
    """The planner's time grid: ``intervals`` equal intervals over [0, tf_s]."""

    intervals: int
    tf_s: float

    @property
    def dt_s(self) -> float:
        return self.tf_s / self.intervals

    def knot(self, k: int) -> float:
        return k * self.dt_s

    def interval(self, k: int) -> tuple[float, float]:
        return self.knot(k), self.knot(k + 1)


def _sub(a: Point, b: Point) -> Point:
    return a[0] - b[0], a[1] - b[1]


class RobotTrajectory:
    """A robot's control points ``cp[k][i]`` (interval k, index i = 0..degree), shared at knots.

    ``label`` names the variables (default the robot's name; the impact-robust planner's copies of one
    robot are ``R1~0`` ... ``R1~3``).
    """

    def __init__(self, model: Model, spec: Body, grid: Grid, degree: int, box: tuple[float, ...],
                 label: str | None = None) -> None:
        self.spec, self.grid, self.degree = spec, grid, degree
        label = label or spec.name
        xmin, xmax, ymin, ymax = box
        self.cp: list[list[Point]] = []
        prev: Point | None = None
        for k in range(grid.intervals):
            row = [prev] if prev is not None else []
            while len(row) < degree + 1:
                i = len(row)
                row.append((model.add_var(xmin, xmax, name=f"{label}.cp[{k}][{i}].x"),
                            model.add_var(ymin, ymax, name=f"{label}.cp[{k}][{i}].y")))
            self.cp.append(row)
            prev = row[-1]

    @classmethod
    def mean(cls, curves: list[RobotTrajectory]) -> RobotTrajectory:
        """The curve whose control points are the mean of ``curves``' (no new variables): a Bezier curve is
        linear in its control points, so this is the pointwise mean of the curves."""
        first = curves[0]
        out = cls.__new__(cls)
        out.spec, out.grid, out.degree = first.spec, first.grid, first.degree
        w = 1.0 / len(curves)
        out.cp = [[(sum((c.cp[k][i][0] for c in curves), LinExpr()) * w,
                    sum((c.cp[k][i][1] for c in curves), LinExpr()) * w)
                   for i in range(first.degree + 1)] for k in range(first.grid.intervals)]
        return out

    def points(self, k: int) -> list[Point]:
        return self.cp[k]

    def position_at_knot(self, k: int) -> Point:
        return self.cp[k][0] if k < self.grid.intervals else self.cp[-1][-1]

    def velocity_start(self, k: int) -> Point:
        """Real velocity (m/s) at the start of interval k."""
        d, dt = self.degree, self.grid.dt_s
        v = _sub(self.cp[k][1], self.cp[k][0])
        return v[0] * (d / dt), v[1] * (d / dt)

    def velocity_end(self, k: int) -> Point:
        """Real velocity (m/s) at the end of interval k."""
        d, dt = self.degree, self.grid.dt_s
        v = _sub(self.cp[k][d], self.cp[k][d - 1])
        return v[0] * (d / dt), v[1] * (d / dt)

    def velocity_points(self, k: int) -> list[Point]:
        d, dt = self.degree, self.grid.dt_s
        return [(v[0] * (d / dt), v[1] * (d / dt)) for v in (_sub(self.cp[k][i + 1], self.cp[k][i]) for i in range(d))]

    def acceleration_points(self, k: int) -> list[Point]:
        d, dt = self.degree, self.grid.dt_s
        c = d * (d - 1) / dt ** 2
        out = []
        for i in range(d - 1):
            p0, p1, p2 = self.cp[k][i], self.cp[k][i + 1], self.cp[k][i + 2]
            out.append(((p2[0] - p1[0] * 2.0 + p0[0]) * c, (p2[1] - p1[1] * 2.0 + p0[1]) * c))
        return out


class ObjectTrajectory:
    """An object's knot positions ``x[k]``, k = 0..N; on interval k it flies straight from x[k] to x[k+1]."""

    def __init__(self, model: Model, spec: Body, grid: Grid, box: tuple[float, ...]) -> None:
        self.spec, self.grid = spec, grid
        xmin, xmax, ymin, ymax = box
        self.x: list[Point] = [(model.add_var(xmin, xmax, name=f"{spec.name}.x[{k}].x"),
                                model.add_var(ymin, ymax, name=f"{spec.name}.x[{k}].y"))
                               for k in range(grid.intervals + 1)]

    def points(self, k: int) -> list[Point]:
        return [self.x[k], self.x[k + 1]]

    def position_at_knot(self, k: int) -> Point:
        return self.x[k]

    def velocity(self, k: int) -> Point:
        """Constant real velocity (m/s) on interval k."""
        v = _sub(self.x[k + 1], self.x[k])
        return v[0] / self.grid.dt_s, v[1] / self.grid.dt_s


def allowed_box(scenario: Scenario, body: Body) -> tuple[float, float, float, float]:
    """The world box shrunk by the body's radius: where its centre may be."""
    xmin, xmax, ymin, ymax = scenario.world_box
    r = body.radius_m
    return xmin + r, xmax - r, ymin + r, ymax - r


def velocity_bound(body: Body) -> tuple[float, float]:
    if body.velocity_bound_mps is None:
        from planners.errors import PlannerError

        raise PlannerError(f"{body.name} has no velocity_bound_mps in the scenario; the planner needs one per body")
    return body.velocity_bound_mps


def add_kinematics(model: Model, robots: list[RobotTrajectory], objects: list[ObjectTrajectory],
                   thrust_fraction: float) -> None:
    """Velocity bounds, thrust-derived acceleration bounds, initial and final states."""
    for r in robots:
        spec = r.spec
        vb = velocity_bound(spec)
        a_max = [thrust_fraction * f / spec.mass_kg for f in spec.wrench_limits[:2]]
        for k in range(r.grid.intervals):
            for p in r.velocity_points(k):
                for axis in range(2):
                    model.add([p[axis] <= vb[axis], p[axis] >= -vb[axis]], group="velocity bounds")
            for p in r.acceleration_points(k):
                for axis in range(2):
                    model.add([p[axis] <= a_max[axis], p[axis] >= -a_max[axis]], group="thrust limits")
        _boundary(model, spec, r.position_at_knot(0), r.velocity_start(0), r.position_at_knot(r.grid.intervals),
                  r.velocity_end(r.grid.intervals - 1))
    for o in objects:
        vb = velocity_bound(o.spec)
        for k in range(o.grid.intervals):
            v = o.velocity(k)
            for axis in range(2):
                model.add([v[axis] <= vb[axis], v[axis] >= -vb[axis]], group="velocity bounds")
        _boundary(model, o.spec, o.position_at_knot(0), o.velocity(0), o.position_at_knot(o.grid.intervals),
                  o.velocity(o.grid.intervals - 1))


def _boundary(model: Model, spec: Body, p0: Point, v0: Point, pf: Point, vf: Point) -> None:
    for axis in range(2):
        model.add(p0[axis] == spec.position_m[axis], group="initial state")
        model.add(v0[axis] == spec.velocity_mps[axis], group="initial state")
        if spec.final_position_m is not None:
            model.add(pf[axis] == spec.final_position_m[axis], group="final state")
        if spec.final_velocity_mps is not None:
            model.add(vf[axis] == spec.final_velocity_mps[axis], group="final state")


def acceleration_l1(model: Model, robots: list[RobotTrajectory]) -> LinExpr:
    """Sum of |acceleration| over the robots' acceleration control points (m/s^2): Eq. 28 in L1 form."""
    total = LinExpr()
    for r in robots:
        for k in range(r.grid.intervals):
            for p in r.acceleration_points(k):
                for axis in range(2):
                    # no upper bound: the cost must never act as a second thrust limit
                    u = model.add_var(0.0, name=f"{r.spec.name}.|acc|")
                    model.add([u >= p[axis], u >= -p[axis]], group="acceleration cost")
                    total = total + u
    return total


def value(point: Point, x: np.ndarray) -> np.ndarray:
    return np.array([point[0].value(x), point[1].value(x)])
