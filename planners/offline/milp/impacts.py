"""Impact assignment, the impact law's encoding and conditional smoothness (paper Eq. 5, 10, 13-14, 23-24).

A binary z[R, O, k] says that robot R hits object O at knot k (interior knots only). Where z = 1 the
positions coincide (Assumption 1: point masses) and the post-impact velocities follow Eq. (5) in REAL
velocities (:mod:`planners.impact_law`), which on the common time grid are linear in the control points.

Where no impact involves a body at a knot its velocity is continuous (Eq. 13-14, 23). Every big-M is the
range of the expression it relaxes, from the world box and the velocity bounds.

The pieces (binaries and assignment, smoothness, the law) are separate functions because the impact-robust
planner applies them to each copy of a robot (``planners/offline/milp/copies.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

from planners.impact_law import Fractions, mass_fractions, point_mass_law
from planners.offline.milp.model import LinExpr, Model
from planners.offline.milp.trajectories import ObjectTrajectory, RobotTrajectory, velocity_bound

__all__ = ["ImpactVars", "add_impacts", "add_object_smoothness", "add_robot_smoothness", "equal_unless",
           "impact_binaries", "law_big_m", "mass_fractions", "point_mass_law"]


@dataclass
class ImpactVars:
    """z[(robot name, object name, knot)] -> binary expression."""

    z: dict[tuple[str, str, int], LinExpr]

    def at(self, robot: str | None = None, obj: str | None = None, knot: int | None = None) -> list[LinExpr]:
        return [v for (r, o, k), v in self.z.items()
                if (robot is None or r == robot) and (obj is None or o == obj) and (knot is None or k == knot)]


def impact_binaries(model: Model, robots: list[RobotTrajectory], objects: list[ObjectTrajectory]) -> ImpactVars:
    """z[R, O, k] for every robot, object and interior knot, with the assignment rows: at a knot an object is
    hit by at most one robot and a robot hits at most one object."""
    n = robots[0].grid.intervals
    z: dict[tuple[str, str, int], LinExpr] = {}
    for r in robots:
        for o in objects:
            for k in range(1, n):
                z[(r.spec.name, o.spec.name, k)] = model.add_binary(name=f"impact[{r.spec.name},{o.spec.name},{k}]")
    iv = ImpactVars(z)
    for k in range(1, n):
        for o in objects:
            zs = iv.at(obj=o.spec.name, knot=k)
            if len(zs) > 1:
                model.add(sum(zs, LinExpr()) <= 1, group="impact assignment")
        for r in robots:
            zs = iv.at(robot=r.spec.name, knot=k)
            if len(zs) > 1:
                model.add(sum(zs, LinExpr()) <= 1, group="impact assignment")
    return iv


def add_robot_smoothness(model: Model, r: RobotTrajectory, iv: ImpactVars, name: str | None = None) -> None:
    """Eq. (14): the robot's velocity is continuous at every knot where it hits nothing. ``name`` is the robot
    whose binaries apply (default ``r``'s own; the impact-robust planner passes each copy of one robot)."""
    name = name or r.spec.name
    vr = velocity_bound(r.spec)
    for k in range(1, r.grid.intervals):
        hit = sum(iv.at(robot=name, knot=k), LinExpr())
        equal_unless(model, r.velocity_start(k), r.velocity_end(k - 1), hit, [2 * vr[0], 2 * vr[1]],
                     "robot smoothness")


def add_object_smoothness(model: Model, o: ObjectTrajectory, iv: ImpactVars) -> None:
    """Eq. (13, 23): the object's velocity is continuous at every knot where nothing hits it."""
    vo = velocity_bound(o.spec)
    for k in range(1, o.grid.intervals):
        hit = sum(iv.at(obj=o.spec.name, knot=k), LinExpr())
        equal_unless(model, o.velocity(k), o.velocity(k - 1), hit, [2 * vo[0], 2 * vo[1]], "object smoothness")


def law_big_m(fractions: Fractions, vr: tuple[float, float],
              vo: tuple[float, float]) -> tuple[list[float], list[float]]:
    """Per-axis ranges of (robot, object) post-impact velocity minus its law value, from the velocity
    bounds: the big-Ms of the impact-law rows."""
    m1, m2, m3, m4 = fractions
    m_rob = [vr[a] + abs(m1) * vr[a] + m2 * vo[a] for a in range(2)]
    m_obj = [vo[a] + m3 * vr[a] + abs(m4) * vo[a] for a in range(2)]
    return m_rob, m_obj


def add_impacts(model: Model, robots: list[RobotTrajectory], objects: list[ObjectTrajectory], restitution: float,
                world_box: tuple[float, float, float, float]) -> ImpactVars:
    """The spatially robust planner's impacts: binaries, smoothness, contact and the point-mass law."""
    n = robots[0].grid.intervals
    iv = impact_binaries(model, robots, objects)
    for r in robots:
        add_robot_smoothness(model, r, iv)
    for o in objects:
        add_object_smoothness(model, o, iv)

    extent = (world_box[1] - world_box[0], world_box[3] - world_box[2])
    for r in robots:
        vr = velocity_bound(r.spec)
        for o in objects:
            fractions = mass_fractions(r.spec.mass_kg, o.spec.mass_kg, restitution)
            m_rob, m_obj = law_big_m(fractions, vr, velocity_bound(o.spec))
            for k in range(1, n):
                miss = 1 - iv.z[(r.spec.name, o.spec.name, k)]
                equal_unless(model, r.position_at_knot(k), o.position_at_knot(k), miss, extent, "impact contact")
                vr_law, vo_law = point_mass_law(fractions, r.velocity_end(k - 1), o.velocity(k - 1))
                equal_unless(model, o.velocity(k), vo_law, miss, m_obj, "impact law")
                equal_unless(model, r.velocity_start(k), vr_law, miss, m_rob, "impact law")
    return iv


def equal_unless(model: Model, a, b, relax: LinExpr, big_m, group: str) -> None:
    """a == b (per axis) when ``relax`` is 0; |a - b| <= big_m[axis] when it is 1."""
    for axis in range(2):
        diff = a[axis] - b[axis]
        model.add([diff <= relax * big_m[axis], diff >= relax * (-big_m[axis])], group=group)
