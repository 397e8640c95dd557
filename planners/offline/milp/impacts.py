"""Impact assignment, the point-mass impact law and conditional smoothness (paper Eq. 5, 10, 13-14, 23-24).

A binary z[R, O, k] says that robot R hits object O at knot k (interior knots only). Where z = 1 the
positions coincide (Assumption 1: point masses) and the post-impact velocities follow Eq. (5) in REAL
velocities, which on the common time grid are linear in the control points:

    v_O+ = m3 v_R- + m4 v_O-,     v_R+ = m1 v_R- + m2 v_O-
    m1 = (m_R - e m_O) / (m_R + m_O),  m2 = (1 + e) m_O / (m_R + m_O),
    m3 = (1 + e) m_R / (m_R + m_O),    m4 = (m_O - e m_R) / (m_R + m_O).

Where no impact involves a body at a knot its velocity is continuous (Eq. 13-14, 23). Every big-M is the
range of the expression it relaxes, from the world box and the velocity bounds.
"""

from __future__ import annotations

from dataclasses import dataclass

from planners.offline.milp.model import LinExpr, Model
from planners.offline.milp.trajectories import ObjectTrajectory, RobotTrajectory, velocity_bound


@dataclass
class ImpactVars:
    """z[(robot name, object name, knot)] -> binary expression."""

    z: dict[tuple[str, str, int], LinExpr]

    def at(self, robot: str | None = None, obj: str | None = None, knot: int | None = None) -> list[LinExpr]:
        return [v for (r, o, k), v in self.z.items()
                if (robot is None or r == robot) and (obj is None or o == obj) and (knot is None or k == knot)]


def mass_fractions(m_r: float, m_o: float, e: float) -> tuple[float, float, float, float]:
    """(m1, m2, m3, m4) of Eq. (5)."""
    s = m_r + m_o
    return (m_r - e * m_o) / s, (1 + e) * m_o / s, (1 + e) * m_r / s, (m_o - e * m_r) / s


def add_impacts(model: Model, robots: list[RobotTrajectory], objects: list[ObjectTrajectory], restitution: float,
                world_box: tuple[float, float, float, float]) -> ImpactVars:
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

    extent = (world_box[1] - world_box[0], world_box[3] - world_box[2])
    for r in robots:
        vr = velocity_bound(r.spec)
        for k in range(1, n):
            hit = sum(iv.at(robot=r.spec.name, knot=k), LinExpr())
            _equal_unless(model, r.velocity_start(k), r.velocity_end(k - 1), hit, [2 * vr[0], 2 * vr[1]],
                          "robot smoothness")
    for o in objects:
        vo = velocity_bound(o.spec)
        for k in range(1, n):
            hit = sum(iv.at(obj=o.spec.name, knot=k), LinExpr())
            _equal_unless(model, o.velocity(k), o.velocity(k - 1), hit, [2 * vo[0], 2 * vo[1]], "object smoothness")

    for r in robots:
        vr = velocity_bound(r.spec)
        for o in objects:
            vo = velocity_bound(o.spec)
            m1, m2, m3, m4 = mass_fractions(r.spec.mass_kg, o.spec.mass_kg, restitution)
            for k in range(1, n):
                miss = 1 - z[(r.spec.name, o.spec.name, k)]
                _equal_unless(model, r.position_at_knot(k), o.position_at_knot(k), miss, extent, "impact contact")
                vr_in, vo_in = r.velocity_end(k - 1), o.velocity(k - 1)
                vo_law = tuple(vr_in[a] * m3 + vo_in[a] * m4 for a in range(2))
                vr_law = tuple(vr_in[a] * m1 + vo_in[a] * m2 for a in range(2))
                m_obj = [vo[a] + m3 * vr[a] + abs(m4) * vo[a] for a in range(2)]
                m_rob = [vr[a] + abs(m1) * vr[a] + m2 * vo[a] for a in range(2)]
                _equal_unless(model, o.velocity(k), vo_law, miss, m_obj, "impact law")
                _equal_unless(model, r.velocity_start(k), vr_law, miss, m_rob, "impact law")
    return iv


def _equal_unless(model: Model, a, b, relax: LinExpr, big_m, group: str) -> None:
    """a == b (per axis) when ``relax`` is 0; |a - b| <= big_m[axis] when it is 1."""
    for axis in range(2):
        diff = a[axis] - b[axis]
        model.add([diff <= relax * big_m[axis], diff >= relax * (-big_m[axis])], group=group)
