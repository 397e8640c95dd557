"""Lemma 1 as constraints: each robot as four copies that reach every vertex of the object's state box.

The paper's Lemma 1: if for every vertex of the object's (interval-hull) state box some robot trajectory
meets it at the impact with the pre-impact velocity that gives the wanted post-impact velocity, then every
state in the box is met by one (the interpolated one). With the state [p_x, p_y, v_x, v_y] that is 2^4 = 16
copies of every robot. Four suffice, exactly:

- Separability. Every constraint on a robot's curve is per axis (Bezier control points, per-axis velocity
  bounds and thrust limits, Eq. 5 per axis), except region faces and separation boxes. A robot's x copy need
  only depend on the object's x vertex (s_p, s_v) in {-1, +1}^2, and its y copy on the y vertex: 4 + 4 per
  axis, not 16. Copy j pairs the x copy and the y copy of the same signs ``SIGNS[j]``; the 16 combinations
  are the products, which region predicates and obstacle faces get as :class:`PointProduct` sets (the
  extreme of n . p over a product is the sum of per-axis extremes: exact), and the separation boxes bound
  per axis anyway.
- Copies are shared away from impacts. All copies pass through the same position and velocity at every
  knot outside the windows of the robot's impacts; they differ only on the ``window`` intervals before an
  impact (to reach the vertex) and after it (to rejoin). The flown curve is their multilinear blend by the
  object's state, which is the mean (the nominal curve) when the object is where it was planned to be. Two
  impacts of one robot are therefore at least 2 ``window`` intervals apart (windows do not overlap), and,
  since the robot commits to its copy blend when the window opens, the object must not be hit inside the
  window before the impact (its state at the impact is then already decided: causality).
- Affine feedback. Copy (s_p, s_v) hits the vertex (c_p + s_p h_p, c_v + s_v h_v) and sends it off with
  t(s) = m3 v_R(s) + m4 (c_v + s_v h_v) (Eq. 5). A blend of the copies by the object's normalised state
  (xi_p, xi_v) gives the object the multilinear blend of t; the rows below require it affine (the cross
  term sum_s s_p s_v v_R(s) = 0), t = t_c + A xi_p + B xi_v, so the post-impact state is again a zonotope
  (``planners/offline/milp/boxes.py``) with A = sum_s s_p t(s) / 4 and B = sum_s s_v t(s) / 4.

Interpolation keeps every linear constraint (velocity bounds, thrust limits, the law) because copies and
blends are convex combinations; regions and obstacles keep it because all copies share the face binaries.
"""

from __future__ import annotations

from impact_env.scenario import Body
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
