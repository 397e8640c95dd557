"""The maths of an impact-robust plan's funnels and copies, and the check of its guarantee.

An object's funnel (:class:`~planners.plan.types.ObjectFunnel`) is its state box on the plan's time grid;
an impact's copies (:class:`~planners.plan.types.ImpactCopies`) are Lemma 1's four curves of the impacting
robot, copy j reaching the object's box vertex with signs ``signs[j] = (s_p, s_v)`` on each axis. For an
object at normalised box coordinates xi = (p - p_nominal) / h_p, (v - v_nominal) / h_v (per axis, in
[-1, 1]) the robot flies their multilinear blend, which meets the object and sends it off with the planned
feedback velocity.

:func:`check_impact_robust` re-derives the guarantee from these numbers alone (no solver): each copy's
contact and the point-mass law (Eq. 5) at its vertex, limits, the copies' sharing with the nominal curve,
the affine feedback, and the box propagation (Eq. 17-19) that the recorded half-widths must contain.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from planners import bezier
from planners.impact_law import mass_fractions
from planners.plan.types import BodyPlan, ImpactCopies, ObjectFunnel, PlanLike

if TYPE_CHECKING:
    from impact_env.transport.scenario import Scenario

__all__ = ["ImpactCopies", "ObjectFunnel", "box_coordinates", "check_impact_robust", "copy_targets", "feedback",
           "pre_velocity_of", "propagate"]


# ------------------------------------------------------------------------------------------------- check
def _segment_at(body: BodyPlan, t0: float, tol: float):
    for s in body.segments:
        if abs(s.t0_s - t0) <= tol:
            return s
    return None


def _velocity(cps: np.ndarray, duration: float, end: bool) -> np.ndarray:
    d = len(cps) - 1
    return d * (cps[-1] - cps[-2] if end else cps[1] - cps[0]) / duration


def check_impact_robust(plan: PlanLike, scenario: Scenario, tol: float) -> list[str]:
    """The violations of an impact-robust plan's guarantee (empty if none); see the module docstring."""
    bad: list[str] = []
    delta = plan.delta_mps
    if delta is None or not np.isfinite(delta) or delta < 0:
        return [f"an impact-robust plan needs delta_mps >= 0, got {delta}"]
    for o in scenario.objects:
        if o.name not in plan.funnels:
            bad.append(f"funnel of {o.name}: missing from the impact-robust plan")
    if len(plan.copies) != len(plan.impacts) or any(
            (c.robot, c.object) != (i.robot, i.object) or abs(c.time_s - i.time_s) > tol
            for c, i in zip(plan.copies, plan.impacts)):
        bad.append("copies: one entry per planned impact is needed, in the same order (same time, robot, object)")
    if bad:
        return bad

    e = scenario.restitution
    for c in plan.copies:
        label = f"copies of {c.robot} at t = {c.time_s:.3f} s"
        robot, obj = plan.bodies[c.robot], plan.bodies[c.object]
        funnel = plan.funnels[c.object]
        k = int(round((c.time_s - funnel.t0_s) / funnel.dt_s))
        if not 1 <= k < funnel.intervals or abs(funnel.t0_s + k * funnel.dt_s - c.time_s) > tol:
            bad.append(f"{label}: not at an interior knot of {c.object}'s funnel")
            continue
        if len(c.signs) != 4 or sorted(map(tuple, c.signs)) != [(-1, -1), (-1, 1), (1, -1), (1, 1)]:
            bad.append(f"{label}: signs must be the four (s_p, s_v) in {{-1, 1}}^2, got {c.signs}")
            continue
        before, after = np.asarray(c.before, dtype=float), np.asarray(c.after, dtype=float)
        if before.ndim != 4 or after.ndim != 4 or len(before) != 4 or len(after) != 4:
            bad.append(f"{label}: before and after must hold 4 copies of (segments, control points, 2) arrays")
            continue
        n_before, n_after = before.shape[1], after.shape[1]
        nominal = [_segment_at(robot, c.window_start_s + i * funnel.dt_s, tol) for i in range(n_before + n_after)]
        if any(s is None for s in nominal) or abs(c.window_start_s + n_before * funnel.dt_s - c.time_s) > tol or \
                abs(c.time_s + n_after * funnel.dt_s - c.window_end_s) > tol or n_before < 1 or n_after < 1:
            bad.append(f"{label}: the window [{c.window_start_s:.3f}, {c.window_end_s:.3f}] s does not match "
                       f"{c.robot}'s segments on the funnel's grid")
            continue
        shapes = {np.shape(s.control_points) for s in nominal}
        if len(shapes) != 1:
            bad.append(f"{label}: {c.robot}'s segments in the window [{c.window_start_s:.3f}, "
                       f"{c.window_end_s:.3f}] s have different numbers of control points")
            continue
        cps = np.array([s.control_points for s in nominal], dtype=float)
        if before.shape[2:] != cps.shape[1:] or after.shape[2:] != cps.shape[1:]:
            bad.append(f"{label}: copies must have {cps.shape[1]} control points like {c.robot}'s segments")
            continue
        chain = np.concatenate([before, after], axis=1)  # (4, W, d + 1, 2)
        if np.max(np.abs(chain.mean(axis=0) - cps)) > tol:
            bad.append(f"{label}: the nominal curve is not the mean of the copies")
        m_r, m_o = scenario.body(c.robot).mass_kg, scenario.body(c.object).mass_kg
        m1, m2, _, _ = mass_fractions(m_r, m_o, e)
        centre = obj.position(c.time_s)
        v_obj = pre_velocity_of(obj, c.time_s)
        hp, hv = funnel.position_halfwidth_m[k], funnel.velocity_halfwidth_mps[k - 1]
        dur = funnel.dt_s
        spec = scenario.body(c.robot)
        for j, (s_p, s_v) in enumerate(c.signs):
            tag = f"{label}, copy {j} (s_p, s_v) = ({s_p:+d}, {s_v:+d})"
            segs = chain[j]
            # shared with the nominal where the window opens and closes
            if np.max(np.abs(segs[0][0] - cps[0][0])) > tol or np.max(np.abs(
                    _velocity(segs[0], dur, False) - _velocity(cps[0], dur, False))) > tol:
                bad.append(f"{tag}: does not start from the nominal state at t = {c.window_start_s:.3f} s")
            if np.max(np.abs(segs[-1][-1] - cps[-1][-1])) > tol or np.max(np.abs(
                    _velocity(segs[-1], dur, True) - _velocity(cps[-1], dur, True))) > tol:
                bad.append(f"{tag}: does not rejoin the nominal state at t = {c.window_end_s:.3f} s")
            for i in range(len(segs) - 1):
                if np.max(np.abs(segs[i][-1] - segs[i + 1][0])) > tol:
                    bad.append(f"{tag}: position jumps inside the window")
                if i + 1 != n_before and np.max(np.abs(_velocity(segs[i], dur, True)
                                                        - _velocity(segs[i + 1], dur, False))) > tol:
                    bad.append(f"{tag}: velocity jumps inside the window away from the impact")
            vertex = centre + s_p * hp
            if np.max(np.abs(before[j][-1][-1] - vertex)) > tol:
                bad.append(f"{tag}: reaches {before[j][-1][-1]}, not the box vertex {vertex}")
            v_in, v_out = _velocity(before[j][-1], dur, True), _velocity(after[j][0], dur, False)
            vo_vertex = v_obj + s_v * hv
            if np.max(np.abs(v_out - (m1 * v_in + m2 * vo_vertex))) > tol:
                bad.append(f"{tag}: post-impact velocity {v_out} breaks Eq. (5) at the vertex")
            for seg_cp in segs:
                v = np.abs(bezier.derivative(seg_cp) / dur).max(axis=0)
                acc = np.abs(bezier.derivative(bezier.derivative(seg_cp)) / dur ** 2).max(axis=0)
                for axis in range(2):
                    if spec.velocity_bound_mps is not None and v[axis] > spec.velocity_bound_mps[axis] + tol:
                        bad.append(f"{tag}: velocity {v[axis]:.4f} m/s exceeds the {'xy'[axis]} bound")
                    if spec.mass_kg * acc[axis] > spec.wrench_limits[axis] * (1 + 1e-9) + tol:
                        bad.append(f"{tag}: needs {spec.mass_kg * acc[axis]:.3f} N along {'xy'[axis]}, more than "
                                   f"the {spec.wrench_limits[axis]} N thrust limit")
        t = copy_targets(c, plan, scenario)
        s = np.asarray(c.signs, dtype=float)
        cross = (s[:, 0] * s[:, 1]) @ t
        if np.max(np.abs(cross)) > 4 * tol:
            bad.append(f"{label}: the copies' feedback is not affine in the box coordinates (cross term {cross})")
        v_after = obj.velocity(c.time_s + 1e-9 * max(1.0, c.time_s))
        if np.max(np.abs(t.mean(axis=0) - v_after)) > tol:
            bad.append(f"{label}: the object's nominal post-impact velocity {v_after} is not the copies' mean "
                       f"{t.mean(axis=0)}")
    for o in scenario.objects:
        funnel = plan.funnels[o.name]
        box = scenario.final_box(o.name)
        if box is not None and (np.any(np.asarray(funnel.final_box_m) > np.asarray(box.position_m) + tol)
                                or np.any(np.asarray(funnel.final_box_mps) > np.asarray(box.velocity_mps) + tol)):
            bad.append(f"funnel of {o.name}: final box {list(funnel.final_box_m)} m, {list(funnel.final_box_mps)} "
                       f"m/s is looser than the scenario's [final_box] {list(box.position_m)} m, "
                       f"{list(box.velocity_mps)} m/s")
        if not bad:
            bad += _check_propagation(funnel, o, scenario, delta, feedback(plan, scenario)[o.name], plan, tol)
    for name in {c.robot for c in plan.copies}:
        windows = sorted((c.window_start_s, c.window_end_s) for c in plan.copies if c.robot == name)
        for (_, end_a), (start_b, _) in zip(windows[:-1], windows[1:]):
            if start_b < end_a - tol:
                bad.append(f"{name}: the copy windows of two of its impacts overlap ({end_a:.3f} s > {start_b:.3f} s)")
    return bad


def box_coordinates(plan: PlanLike, c: ImpactCopies, position: np.ndarray, velocity: np.ndarray) -> np.ndarray:
    """The object's normalised pre-impact box coordinates xi = [[xi_p_x, xi_v_x], [xi_p_y, xi_v_y]] at the
    impact of ``c`` for its state (position at the impact, velocity just before): 0 at the nominal, +-1 on
    the box faces (a zero half-width gives 0: that coordinate is known)."""
    funnel, obj = plan.funnels[c.object], plan.bodies[c.object]
    k = int(round((c.time_s - funnel.t0_s) / funnel.dt_s))
    hp, hv = funnel.position_halfwidth_m[k], funnel.velocity_halfwidth_mps[k - 1]
    dp = np.asarray(position, dtype=float) - obj.position(c.time_s)
    dv = np.asarray(velocity, dtype=float) - pre_velocity_of(obj, c.time_s)
    xi_p = np.divide(dp, hp, out=np.zeros(2), where=hp > 1e-12)
    xi_v = np.divide(dv, hv, out=np.zeros(2), where=hv > 1e-12)
    return np.stack([xi_p, xi_v], axis=1)


def copy_targets(c: ImpactCopies, plan: PlanLike, scenario: Scenario) -> np.ndarray:
    """(4, 2): the velocity each copy sends its box vertex off with, by Eq. (5) (before the noise)."""
    funnel, obj = plan.funnels[c.object], plan.bodies[c.object]
    k = int(round((c.time_s - funnel.t0_s) / funnel.dt_s))
    _, _, m3, m4 = mass_fractions(scenario.body(c.robot).mass_kg, scenario.body(c.object).mass_kg,
                                  scenario.restitution)
    v_obj, hv = pre_velocity_of(obj, c.time_s), funnel.velocity_halfwidth_mps[k - 1]
    return np.array([m3 * _velocity(np.asarray(b)[-1], funnel.dt_s, True) + m4 * (v_obj + s_v * hv)
                     for b, (_, s_v) in zip(c.before, c.signs)])


def feedback(plan: PlanLike, scenario: Scenario) -> dict[str, dict[int, tuple[np.ndarray, np.ndarray]]]:
    """Per object and impact knot, the copies' feedback (A, B) per axis: the object leaves the impact with
    v_nominal + A xi_p + B xi_v (+ the error) for normalised pre-impact box coordinates xi."""
    out: dict[str, dict[int, tuple[np.ndarray, np.ndarray]]] = {name: {} for name in plan.funnels}
    for c in plan.copies:
        funnel = plan.funnels[c.object]
        t, s = copy_targets(c, plan, scenario), np.asarray(c.signs, dtype=float)
        out[c.object][int(round((c.time_s - funnel.t0_s) / funnel.dt_s))] = (s[:, 0] @ t / 4.0, s[:, 1] @ t / 4.0)
    return out


def propagate(funnel: ObjectFunnel, delta: float, feedback: dict[int, tuple[np.ndarray, np.ndarray]]
              ) -> tuple[np.ndarray, np.ndarray]:
    """Eq. (17-19): the exact position (N + 1, 2) and velocity (N, 2) half-widths of the object's zonotope,
    from zero, with the recorded position half-width and the copies' feedback at each impact knot."""
    n, dt = funnel.intervals, funnel.dt_s
    hp_rec = np.asarray(funnel.position_halfwidth_m)
    hp, hv = np.zeros((n + 1, 2)), np.zeros((n, 2))
    gp, gv = np.zeros((3, 2)), np.zeros((3, 2))  # generators (position-type, velocity-type, noise) per axis
    for k in range(1, n + 1):
        gp = gp + dt * gv
        hp[k] = np.abs(gp).sum(axis=0)
        if k == n:
            break
        if k in feedback:
            a_fb, b_fb = feedback[k]
            # the copies span the recorded box (>= the spread): the reset starts from it
            gp = np.array([hp_rec[k], np.zeros(2), np.zeros(2)])
            gv = np.array([a_fb, b_fb, np.full(2, delta)])
        hv[k] = np.abs(gv).sum(axis=0)
    return hp, hv


def pre_velocity_of(body: BodyPlan, t: float) -> np.ndarray:
    """The body's velocity just before t (the segment that ends at t)."""
    for s in body.segments:
        if s.t0_s < t <= s.t1_s + 1e-12:
            return s.velocity(s.t1_s)[0] if abs(s.t1_s - t) < 1e-9 else s.velocity(t)[0]
    return body.segments[0].velocity(t)[0]


def _check_propagation(funnel: ObjectFunnel, spec, scenario: Scenario, delta: float,
                       fb: dict[int, tuple[np.ndarray, np.ndarray]], plan: PlanLike, tol: float) -> list[str]:
    """Eq. (17-19) re-run from the copies' feedback: the recorded half-widths must contain the zonotope, and
    the box must stay in the world, within the velocity bounds and end in the final box."""
    bad = []
    n = funnel.intervals
    hp, hv = np.asarray(funnel.position_halfwidth_m), np.asarray(funnel.velocity_halfwidth_mps)
    label = f"funnel of {spec.name}"
    if hp.shape != (n + 1, 2) or hv.shape != (n, 2):
        return [f"{label}: half-widths must be ({n + 1}, 2) and ({n}, 2), got {hp.shape} and {hv.shape}"]
    body = plan.bodies[spec.name]
    if len(body.segments) != n or abs(body.segments[-1].t1_s - funnel.knots_s[-1]) > tol:
        return [f"{label}: its grid does not match {spec.name}'s {len(body.segments)} segments"]
    need_p, need_v = propagate(funnel, delta, fb)
    xmin, xmax, ymin, ymax = scenario.world_box
    lo = np.array([xmin, ymin]) + spec.radius_m
    hi = np.array([xmax, ymax]) - spec.radius_m
    for k in range(n + 1):
        t = funnel.knots_s[k]
        if np.any(hp[k] < need_p[k] - tol):
            bad.append(f"{label}: position half-width {hp[k]} at t = {t:.3f} s is smaller than the propagated "
                       f"spread {need_p[k]}")
        c = body.position(t)
        if np.any(c + hp[k] > hi + tol) or np.any(c - hp[k] < lo - tol):
            bad.append(f"{label}: the box at t = {t:.3f} s leaves the world box")
        if k == n:
            break
        if np.any(hv[k] < need_v[k] - tol):
            bad.append(f"{label}: velocity half-width {hv[k]} on interval {k} is smaller than the spread {need_v[k]}")
        v = body.segments[k].velocity(body.segments[k].t0_s)[0]
        if spec.velocity_bound_mps is not None and np.any(np.abs(v) + hv[k] > np.array(spec.velocity_bound_mps) + tol):
            bad.append(f"{label}: velocities on interval {k} exceed the object's velocity bound")
    if np.any(hp[n] > np.asarray(funnel.final_box_m) + tol) or \
            np.any(hv[n - 1] > np.asarray(funnel.final_box_mps) + tol):
        bad.append(f"{label}: final half-widths {hp[n]} m, {hv[n - 1]} m/s exceed the final box "
                   f"{list(funnel.final_box_m)} m, {list(funnel.final_box_mps)} m/s")
    return bad
