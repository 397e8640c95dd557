"""The object's uncertain state on the time grid (paper Eq. 17-19): a zonotope per axis, its box, and delta.

The planner's point-mass model is separable per axis, so the object's state set is a product of one set per
axis in the (position, velocity) plane. After every impact it is

    (p, v) = (c_p, c_v) + xi_1 (h_p, A) + xi_2 (0, B) + xi_3 (0, delta),      xi in [-1, 1]^3

(the position spread with the copies' feedback A, their answer B to the velocity spread, and the new error of
at most delta, Eq. 18). Free flight maps every generator (g_p, g_v) to (g_p + dt g_v, g_v) (Eq. 19), linear
on the fixed grid; the box at knot k has half-widths h_p >= sum |g_p|, h_v >= sum |g_v|. Which impact was
last is decided by the impact binaries through big-M rows, each big-M a range the model implies; no term is
bilinear. The derivation: ``docs/planner_design.md#object-boxes``.
"""

from __future__ import annotations

from planners.offline.milp.impacts import ImpactVars
from planners.offline.milp.model import LinExpr, Model
from planners.offline.milp.stl_encoding import PointProduct
from planners.offline.milp.trajectories import ObjectTrajectory, velocity_bound

GENERATORS = 3  # position-type (h_p, A), velocity-type (0, B), noise (0, delta)


class ObjectBox:
    """The state set of one object around its nominal trajectory ``centre`` (the box centre).

    gp[k][i][a], gv[k][i][a]: generator i (0..2) on axis a of the state on interval k (after any impact at
    knot k), expressions built by :meth:`add_propagation`. hp[k][a]: position half-width at knot k
    (k = 0..N). hv[k][a]: velocity half-width on interval k (k = 0..N-1). Index 0 is the known initial state
    (all zero).
    """

    def __init__(self, model: Model, centre: ObjectTrajectory, allowed: tuple[float, float, float, float],
                 delta: LinExpr, delta_ub: float) -> None:
        self.centre, self.delta, self.delta_ub = centre, delta, delta_ub
        self.spec, self.grid = centre.spec, centre.grid
        n, name = self.grid.intervals, self.spec.name
        self.allowed = allowed
        self.half_extent = ((allowed[1] - allowed[0]) / 2.0, (allowed[3] - allowed[2]) / 2.0)
        self.vmax = velocity_bound(self.spec)
        zero = [[LinExpr() for _ in range(2)] for _ in range(GENERATORS)]
        self.gp: list[list[list[LinExpr]]] = [zero]
        self.gv: list[list[list[LinExpr]]] = [zero]
        self.hp: list[list[LinExpr]] = [[LinExpr(), LinExpr()]]
        self.hp += [[model.add_var(0.0, self.half_extent[a], name=f"{name}.hp[{k}].{'xy'[a]}") for a in range(2)]
                    for k in range(1, n + 1)]
        self.hv: list[list[LinExpr]] = [[LinExpr(), LinExpr()]]
        self.hv += [[model.add_var(0.0, self.vmax[a], name=f"{name}.hv[{k}].{'xy'[a]}") for a in range(2)]
                    for k in range(1, n)]

    # ------------------------------------------------------------------------------------ expressions
    def pre_gp(self, k: int, i: int, a: int) -> LinExpr:
        """Position part of generator i on axis a just before knot k (free flight over interval k-1)."""
        return self.gp[k - 1][i][a] + self.gv[k - 1][i][a] * self.grid.dt_s

    def vertex_position(self, k: int, s_p: int, a: int) -> LinExpr:
        """Position on axis a of the box vertex on side ``s_p`` (-1 or +1) at knot k."""
        return self.centre.position_at_knot(k)[a] + self.hp[k][a] * float(s_p)

    def vertex_velocity_before(self, k: int, s_v: int, a: int) -> LinExpr:
        """Velocity on axis a of the box vertex on side ``s_v`` just before knot k (interval k-1)."""
        return self.centre.velocity(k - 1)[a] + self.hv[k - 1][a] * float(s_v)

    def corners(self, k: int) -> PointProduct:
        """The four corners of the position box at knot k."""
        c = self.centre.position_at_knot(k)
        return PointProduct(tuple(c[0] + self.hp[k][0] * s for s in (-1.0, 1.0)),
                            tuple(c[1] + self.hp[k][1] * s for s in (-1.0, 1.0)))

    def point_sets(self, k: int) -> list[PointProduct]:
        """Where the object can be on interval k: a straight flight between a point of the box at knot k and
        one of the box at k + 1 stays in the hull of their corners."""
        return [self.corners(k), self.corners(k + 1)]

    # ------------------------------------------------------------------------------------- constraints
    def add_propagation(self, model: Model, impacts: ImpactVars,
                        resets: dict[tuple[str, int], tuple[list[LinExpr], list[LinExpr], float]],
                        disjunctive: bool = True) -> None:
        """Box half-widths, free flight, and the impact resets, as the convex hull of each knot's disjunction.

        ``resets[(robot, k)] = (A per axis, B per axis, bound of |A| and |B|)``: the feedback that robot's
        copies give when it hits this object at knot k (``planners/offline/milp/copies.py``).

        At knot k, with y = sum of the impact binaries on this object there, the pre-impact generators P
        are split as P = Q + H, |Q| <= M (1 - y), |H| <= M y (Q: the part that flies on, H: the part that is
        hit), and the generators after the knot are Q + (h_H, A_H), (0, B_H), (0, delta_H) with
        h_H >= sum |H_p| (the hit part's box), |A_H|, |B_H| <= bound * y and delta_H = delta y (exact for a
        binary y: delta_H in [delta - delta_max (1 - y), delta], [0, delta_max y]). For y in {0, 1} this is
        exactly free flight or the reset; for a fractional y it is the convex hull of the two (Balas'
        disjunctive formulation), much tighter than big-M rows switching the generators: there, a fraction of
        an impact could reset a whole spread, and the LP bound on delta never left its cap. The bounds M are
        L and V, except for the noise generator: its position part is at most delta_max t_k (it grows by at
        most delta_max per second from t = 0), which halved HiGHS's nodes on obstacle_avoidance.
        ``disjunctive=False`` switches the generators with big-M rows instead (the baseline of
        ``benchmarks/planner.py``; same optimum, weaker relaxation).
        """
        n, name = self.grid.intervals, self.spec.name
        L, V, d_ub = self.half_extent, self.vmax, self.delta_ub
        group = "box propagation"
        for k in range(1, n):
            hit = sum(impacts.at(obj=name, knot=k), LinExpr())
            miss = 1 - hit
            here = [(robot, fb) for (robot, knot), fb in resets.items() if knot == k]
            if not disjunctive:
                self._switch_big_m(model, impacts, k, hit, here)
                continue
            d_h = model.add_var(0.0, d_ub, name=f"{name}.delta_hit[{k}]")
            model.add([d_h <= self.delta, d_h <= hit * d_ub, d_h >= self.delta - miss * d_ub], group="impact reset")
            # every entry is set below, per axis
            gp_k = [[LinExpr(), LinExpr()] for _ in range(GENERATORS)]
            gv_k = [[LinExpr(), LinExpr()] for _ in range(GENERATORS)]
            for a in range(2):
                h_spread = LinExpr()
                q_p, q_v = [], []
                for i in range(GENERATORS):
                    lo_p, lo_v = (0.0, 0.0) if i == 2 else (-L[a], -V[a])
                    m_v = d_ub if i == 2 else V[a]
                    # the noise generator's position part is at most delta_max times the time flown
                    m_p = min(L[a], d_ub * self.grid.knot(k)) if i == 2 else L[a]
                    qp = model.add_var(lo_p, m_p, name=f"{name}.fly_p[{k}][{i}]")
                    qv = model.add_var(lo_v, m_v, name=f"{name}.fly_v[{k}][{i}]")
                    hp_i = self.pre_gp(k, i, a) - qp
                    hv_i = self.gv[k - 1][i][a] - qv
                    for part, big, lower in ((qp, m_p * miss, lo_p), (qv, miss * m_v, lo_v),
                                             (hp_i, hit * m_p, lo_p), (hv_i, hit * m_v, lo_v)):
                        model.add(part <= big, group=group)
                        model.add(part >= (big * -1.0 if lower < 0 else 0.0), group=group)
                    q_p.append(qp)
                    q_v.append(qv)
                    if i == 2:
                        h_spread = h_spread + hp_i
                    else:
                        u = model.add_var(0.0, L[a], name=f"{name}.|hit_p|[{k}][{i}]")
                        model.add([u >= hp_i, u >= -hp_i], group=group)
                        h_spread = h_spread + u
                # the hit part's box: its spread, and the box the copies reach (hp) when the impact happens
                h_h = model.add_var(0.0, L[a], name=f"{name}.hp_hit[{k}].{'xy'[a]}")
                model.add([h_h >= h_spread, h_h <= hit * L[a], h_h - self.hp[k][a] <= miss * L[a],
                           self.hp[k][a] - h_h <= miss * L[a]], group="impact reset")
                a_h = model.add_var(-V[a], V[a], name=f"{name}.A_hit[{k}].{'xy'[a]}")
                b_h = model.add_var(-V[a], V[a], name=f"{name}.B_hit[{k}].{'xy'[a]}")
                for var in (a_h, b_h):
                    model.add([var <= hit * V[a], var >= hit * (-V[a])], group="impact reset")
                for robot, (a_fb, b_fb, m_fb) in here:
                    rmiss = 1 - impacts.z[(robot, name, k)]
                    _equal_unless(model, a_h, a_fb[a], rmiss, V[a] + m_fb, "impact reset")
                    _equal_unless(model, b_h, b_fb[a], rmiss, V[a] + m_fb, "impact reset")
                gp_k[0][a], gv_k[0][a] = q_p[0] + h_h, q_v[0] + a_h
                gp_k[1][a], gv_k[1][a] = q_p[1], q_v[1] + b_h
                gp_k[2][a], gv_k[2][a] = q_p[2], q_v[2] + d_h
            self.gp.append(gp_k)
            self.gv.append(gv_k)

        for k in range(1, n + 1):
            for a in range(2):
                gens = [self.pre_gp(k, i, a) for i in range(GENERATORS)]
                model.add(self.hp[k][a] >= _l1_bound(model, gens, L[a], f"{name}.|gp|[{k}]", group), group=group)
        for k in range(1, n):
            for a in range(2):
                gens = [self.gv[k][i][a] for i in range(GENERATORS)]
                model.add(self.hv[k][a] >= _l1_bound(model, gens, V[a], f"{name}.|gv|[{k}]", group), group=group)

    def _switch_big_m(self, model: Model, impacts: ImpactVars, k: int, hit: LinExpr,
                      here: list[tuple[str, tuple[list[LinExpr], list[LinExpr], float]]]) -> None:
        """The generators after knot k as variables switched by big-M rows: free flight unless hit, the reset
        of the robot that hits otherwise (each M the range of the difference it relaxes)."""
        name, L, V, d_ub = self.spec.name, self.half_extent, self.vmax, self.delta_ub
        gp = [[model.add_var(0.0 if i == 2 else -L[a], L[a], name=f"{name}.gp[{k}][{i}]") for a in range(2)]
              for i in range(GENERATORS)]
        gv = [[model.add_var(0.0 if i == 2 else -V[a], d_ub if i == 2 else V[a], name=f"{name}.gv[{k}][{i}]")
               for a in range(2)] for i in range(GENERATORS)]
        for i in range(GENERATORS):
            for a in range(2):
                _equal_unless(model, gp[i][a], self.pre_gp(k, i, a), hit, 2 * L[a], "box propagation")
                _equal_unless(model, gv[i][a], self.gv[k - 1][i][a], hit, d_ub if i == 2 else 2 * V[a],
                              "box propagation")
        for robot, (a_fb, b_fb, m_fb) in here:
            miss = 1 - impacts.z[(robot, name, k)]
            for a in range(2):
                _equal_unless(model, gp[0][a], self.hp[k][a], miss, 2 * L[a], "impact reset")
                _equal_unless(model, gp[1][a], LinExpr(), miss, L[a], "impact reset")
                _equal_unless(model, gp[2][a], LinExpr(), miss, L[a], "impact reset")
                _equal_unless(model, gv[0][a], a_fb[a], miss, V[a] + m_fb, "impact reset")
                _equal_unless(model, gv[1][a], b_fb[a], miss, V[a] + m_fb, "impact reset")
                _equal_unless(model, gv[2][a], self.delta, miss, d_ub, "impact reset")
        self.gp.append(gp)
        self.gv.append(gv)

    def add_bounds(self, model: Model) -> None:
        """The whole box inside the object's allowed region, and its velocities within the bounds."""
        n = self.grid.intervals
        lo = (self.allowed[0], self.allowed[2])
        hi = (self.allowed[1], self.allowed[3])
        for k in range(1, n + 1):
            c = self.centre.position_at_knot(k)
            for a in range(2):
                model.add([c[a] + self.hp[k][a] <= hi[a], c[a] - self.hp[k][a] >= lo[a]], group="world box")
        for k in range(1, n):
            v = self.centre.velocity(k)
            for a in range(2):
                model.add([v[a] + self.hv[k][a] <= self.vmax[a], v[a] - self.hv[k][a] >= -self.vmax[a]],
                          group="velocity bounds")

    def add_final_box(self, model: Model, position_m: tuple[float, float], velocity_mps: tuple[float, float]) -> None:
        """The final state set inside the final-state box around the planned final state."""
        n = self.grid.intervals
        for a in range(2):
            model.add(self.hp[n][a] <= position_m[a], group="final box")
            model.add(self.hv[n - 1][a] <= velocity_mps[a], group="final box")


def _l1_bound(model: Model, gens: list[LinExpr], cap: float, name: str, group: str) -> LinExpr:
    """sum_i |g_i| of a box's generators along one axis, one variable u_i >= |g_i| (at most ``cap``) per
    signed generator; the last generator (the newest post-impact error) is non-negative and enters as is."""
    bound = LinExpr()
    for i, g in enumerate(gens):
        if i == 2:  # non-negative
            bound = bound + g
            continue
        u = model.add_var(0.0, cap, name=f"{name}[{i}]")
        model.add([u >= g, u >= -g], group=group)
        bound = bound + u
    return bound


def _equal_unless(model: Model, a: LinExpr, b: LinExpr, relax: LinExpr, big_m: float, group: str) -> None:
    diff = a - b
    model.add([diff <= relax * big_m, diff >= relax * (-big_m)], group=group)
