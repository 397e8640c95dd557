"""Lemma 1 as constraints: each robot as four copies that reach every vertex of the object's state box.

The paper's Lemma 1: if for every vertex of the object's (interval-hull) state box some robot trajectory
meets it with the pre-impact velocity that gives the wanted post-impact velocity, every state in the box is
met by one (the interpolated one). That is 2^4 = 16 copies of every robot; four suffice, exactly, because
every constraint on a robot's curve is per axis (copy j pairs the x and the y copy of signs ``SIGNS[j]``;
region predicates and obstacle faces see the 16 combinations as :class:`PointProduct` sets). The copies are
shared away from impacts and differ only on ``window`` intervals around one, and the rows require their
feedback to be affine, t = t_c + A xi_p + B xi_v, so that the post-impact state is again a zonotope
(``planners/offline/milp/boxes.py``). The argument in full: ``docs/planner_design.md#robot-copies``.
"""

from __future__ import annotations

from impact_env.transport.scenario import Body
from planners.impact_law import mass_fractions, point_mass_law
from planners.offline.milp.boxes import ObjectBox
from planners.offline.milp.impacts import ImpactVars, add_robot_smoothness, equal_unless, law_big_m
from planners.offline.milp.model import LinExpr, Model
from planners.offline.milp.stl_encoding import PointProduct
from planners.offline.milp.trajectories import Grid, Point, RobotTrajectory, velocity_bound

SIGNS: tuple[tuple[int, int], ...] = ((-1, -1), (-1, 1), (1, -1), (1, 1))  # (s_p, s_v) of copy j, both axes


class RobotCopies:
    """Four copies of one robot's Bezier chain; ``nominal`` is their mean (no variables of its own)."""

    def __init__(self, model: Model, spec: Body, grid: Grid, degree: int, box: tuple[float, ...]) -> None:
        self.spec, self.grid, self.degree = spec, grid, degree
        self.copies = [RobotTrajectory(model, spec, grid, degree, box, label=f"{spec.name}~{j}")
                       for j in range(len(SIGNS))]
        self.nominal = RobotTrajectory.mean(self.copies)

    def points(self, k: int) -> list[Point]:
        """Every copy's control points on interval k (for bounding boxes)."""
        return [p for c in self.copies for p in c.points(k)]

    def point_sets(self, k: int) -> list[PointProduct]:
        """Per control-point index, the product of the copies' x and y values: every curve a blend of the
        copies can fly on interval k lies in their hull."""
        return [PointProduct(tuple(c.cp[k][i][0] for c in self.copies), tuple(c.cp[k][i][1] for c in self.copies))
                for i in range(self.degree + 1)]

    def acceleration_points(self, k: int) -> list[Point]:
        return [p for c in self.copies for p in c.acceleration_points(k)]


def add_copy_impacts(model: Model, robots: list[RobotCopies], boxes: list[ObjectBox], impacts: ImpactVars,
                     restitution: float, world_box: tuple[float, float, float, float], window: int = 1
                     ) -> dict[str, dict[tuple[str, int], tuple[list[LinExpr], list[LinExpr], float]]]:
    """Smoothness and sharing of the copies, and Lemma 1's contact and impact law for every copy.

    ``window``: the copies may differ on this many grid intervals before and after an impact (more room to
    reach a vertex within the thrust limits; it costs spacing between a robot's impacts and, for causality,
    no other impact on the object inside the window before the impact).

    Returns per object the resets its box needs: ``{(robot, knot): (A per axis, B per axis, big-M)}``.
    """
    n = robots[0].grid.intervals
    extent = (world_box[1] - world_box[0], world_box[3] - world_box[2])
    resets: dict[str, dict[tuple[str, int], tuple[list[LinExpr], list[LinExpr], float]]] = {
        b.spec.name: {} for b in boxes}
    for r in robots:
        name, vr = r.spec.name, velocity_bound(r.spec)
        for c in r.copies:
            add_robot_smoothness(model, c, impacts, name=name)
        first = r.copies[0]
        w = window
        for k in range(1, n):
            # copies differ at knot k only inside the window of one of the robot's impacts
            near = sum((z for j in range(max(1, k - w + 1), min(n - 1, k + w - 1) + 1)
                        for z in impacts.at(robot=name, knot=j)), LinExpr())
            for c in r.copies[1:]:
                equal_unless(model, c.position_at_knot(k), first.position_at_knot(k), near, extent, "robot copies")
                equal_unless(model, c.velocity_start(k), first.velocity_start(k), near, [2 * vr[0], 2 * vr[1]],
                             "robot copies")
            # two impacts of one robot at least 2 w intervals apart: their windows do not overlap
            hit = sum(impacts.at(robot=name, knot=k), LinExpr())
            for j in range(k + 1, min(n - 1, k + 2 * w - 1) + 1):
                model.add(hit + sum(impacts.at(robot=name, knot=j), LinExpr()) <= 1, group="robot copies")
        for box in boxes:
            # causality: the copies commit to a vertex w intervals before the impact, so the object's state
            # at the impact must be decided by then (no impact on it inside the window)
            for k in range(1, n):
                z = impacts.z[(name, box.spec.name, k)]
                for j in range(max(1, k - w + 1), k):
                    others = sum(impacts.at(obj=box.spec.name, knot=j), LinExpr())
                    model.add(z + others <= 1, group="robot copies")

        for box in boxes:
            o = box.centre
            vo = velocity_bound(o.spec)
            fractions = mass_fractions(r.spec.mass_kg, o.spec.mass_kg, restitution)
            _, _, m3, m4 = fractions
            m_rob, m_obj = law_big_m(fractions, vr, vo)
            for k in range(1, n):
                miss = 1 - impacts.z[(name, o.spec.name, k)]
                v_in = [c.velocity_end(k - 1) for c in r.copies]
                for c, (s_p, s_v), vr_in in zip(r.copies, SIGNS, v_in):
                    vertex = tuple(box.vertex_position(k, s_p, a) for a in range(2))
                    vo_in = tuple(box.vertex_velocity_before(k, s_v, a) for a in range(2))
                    equal_unless(model, c.position_at_knot(k), vertex, miss, extent, "impact contact")
                    vr_law, _ = point_mass_law(fractions, vr_in, vo_in)
                    equal_unless(model, c.velocity_start(k), vr_law, miss, m_rob, "impact law")
                # the box centre obeys Eq. (5) with the nominal robot (the mean of the copies)
                nominal_in = r.nominal.velocity_end(k - 1)
                _, vo_law = point_mass_law(fractions, nominal_in, o.velocity(k - 1))
                equal_unless(model, o.velocity(k), vo_law, miss, m_obj, "impact law")
                cross = tuple(sum((v[a] * float(s_p * s_v) for v, (s_p, s_v) in zip(v_in, SIGNS)), LinExpr())
                              for a in range(2))
                equal_unless(model, cross, (LinExpr(), LinExpr()), miss, [4 * vr[0], 4 * vr[1]], "impact law")
                a_fb = [sum((v[a] * float(s_p) for v, (s_p, _) in zip(v_in, SIGNS)), LinExpr()) * (m3 / 4)
                        for a in range(2)]
                b_fb = [sum((v[a] * float(s_v) for v, (_, s_v) in zip(v_in, SIGNS)), LinExpr()) * (m3 / 4)
                        + box.hv[k - 1][a] * m4 for a in range(2)]
                # |A| <= m3 v_R and |B| <= m3 v_R + |m4| v_O: with |g_v| <= v_O, the reset rows' big-M
                m_fb = max(m3 * vr[a] + abs(m4) * vo[a] for a in range(2))
                resets[o.spec.name][(name, k)] = (a_fb, b_fb, m_fb)
    return resets
