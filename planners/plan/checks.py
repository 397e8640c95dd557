"""The checks of a plan against its scenario: what :meth:`Plan.check <planners.plan.Plan.check>` verifies.

:data:`PLAN_CHECKS` lists them in order, each a function ``(plan, scenario, tol) -> violations``; a new plan
feature adds its check there. The structural checks come first: when one fails, the later ones (which index
bodies and evaluate curves) are skipped. An impact-robust plan's funnels and copies are checked by
:func:`planners.plan.funnels.check_impact_robust`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from planners.errors import PlanCheckError
from planners.plan.funnels import check_impact_robust, pre_velocity_of
from planners.plan.schema import MAX_DEGREE
from planners.plan.types import BodyPlan, PlanLike, PlannedImpact

if TYPE_CHECKING:
    from impact_env.transport.scenario import Scenario

__all__ = ["PLAN_CHECKS", "check_plan"]


def check_plan(plan: PlanLike, scenario: Scenario, tol: float = 1e-6) -> None:
    """Run :data:`PLAN_CHECKS` in order; raise :class:`PlanCheckError` listing every violation."""
    bad: list[str] = []
    for check in PLAN_CHECKS:
        bad += check(plan, scenario, tol)
        if bad and check in _STRUCTURAL:  # later checks index bodies and segments that must exist
            break
    if bad:
        raise PlanCheckError(bad)


def _check_structure(plan: PlanLike, scenario: Scenario, tol: float) -> list[str]:
    """The plan has the scenario's bodies with the right kinds, and well-formed, finite segments."""
    bad = []
    if not isinstance(plan.bodies, dict):
        return [f"bodies must be a dict name -> BodyPlan, got {type(plan.bodies).__name__}"]
    kinds = {b.name: ("robot" if b.is_robot else "object") for b in scenario.bodies}
    for name in plan.bodies:
        if name not in kinds:
            bad.append(f"{name}: in the plan but not in scenario {scenario.name!r} (bodies: {', '.join(kinds)})")
    for name, kind in kinds.items():
        body = plan.bodies.get(name)
        if body is None:
            bad.append(f"{name}: missing from the plan")
            continue
        if body.kind != kind:
            bad.append(f"{name}: kind {body.kind!r} in the plan, but it is a {kind} in the scenario")
        if not body.segments:
            bad.append(f"{name}: has no segments")
        for k, seg in enumerate(body.segments):
            cp = np.asarray(seg.control_points)
            if cp.ndim != 2 or cp.shape[1] != 2 or not 2 <= len(cp) <= MAX_DEGREE + 1:
                bad.append(f"{name}: segment {k} control points have shape {cp.shape}, need (degree + 1, 2) with "
                           f"degree 1..{MAX_DEGREE}")
            elif not np.all(np.isfinite(cp.astype(float))):
                bad.append(f"{name}: segment {k} has non-finite control points")
            if not (math.isfinite(seg.t0_s) and math.isfinite(seg.t1_s)):
                bad.append(f"{name}: segment {k} has non-finite times [{seg.t0_s}, {seg.t1_s}]")
    return bad


def _check_impact_records(plan: PlanLike, scenario: Scenario, tol: float) -> list[str]:
    """Each impact names a robot and an object of the scenario, at a time in [0, tf], with finite 2-D numbers;
    no impact is listed twice."""
    bad = []
    kinds = {b.name: ("robot" if b.is_robot else "object") for b in scenario.bodies}
    seen: list[tuple[str, str, float]] = []
    for k, imp in enumerate(plan.impacts):
        label = f"impacts[{k}]"
        for role in ("robot", "object"):
            who = getattr(imp, role)
            if kinds.get(who) != role:
                bad.append(f"{label}: {role} {who!r} is not {'a' if role == 'robot' else 'an'} {role} of scenario "
                           f"{scenario.name!r} ({role}s: {', '.join(n for n, r in kinds.items() if r == role)})")
        if not (isinstance(imp.time_s, (int, float)) and 0.0 <= imp.time_s <= scenario.tf_s + tol):
            bad.append(f"{label}: time {imp.time_s} s is outside [0, {scenario.tf_s}] s")
        for key in ("position", "object_velocity_before", "object_velocity_after", "robot_velocity_before",
                    "robot_velocity_after"):
            value = np.asarray(getattr(imp, key), dtype=float)
            if value.shape != (2,) or not np.all(np.isfinite(value)):
                bad.append(f"{label}: {key} must be 2 finite numbers, got {getattr(imp, key)!r}")
        for r, o, t in seen:
            if (r, o) == (imp.robot, imp.object) and abs(t - imp.time_s) <= tol:
                bad.append(f"{label}: {imp.robot}->{imp.object} at t = {imp.time_s} s is listed twice")
        seen.append((imp.robot, imp.object, imp.time_s))
    return bad


def _check_trajectories(plan: PlanLike, scenario: Scenario, tol: float) -> list[str]:
    bad = []
    for spec in scenario.bodies:
        impact_times = [i.time_s for i in plan.impacts if spec.name in (i.robot, i.object)]
        bad += _check_body(plan.bodies[spec.name], spec, scenario.tf_s, impact_times, tol)
    return bad


def _check_impact_laws(plan: PlanLike, scenario: Scenario, tol: float) -> list[str]:
    bad = []
    for imp in plan.impacts:
        bad += _check_impact(plan, imp, scenario, tol)
    return bad


def _check_body(body: BodyPlan, spec, tf_s: float, impact_times: list[float], tol: float) -> list[str]:
    bad = []
    n = body.name
    segs = body.segments
    if abs(segs[0].t0_s) > tol or abs(segs[-1].t1_s - tf_s) > tol:
        bad.append(f"{n}: segments span [{segs[0].t0_s}, {segs[-1].t1_s}] s, not [0, {tf_s}] s")
    for k, (a, b) in enumerate(zip(segs[:-1], segs[1:])):
        if abs(a.t1_s - b.t0_s) > tol:
            bad.append(f"{n}: segment {k} ends at {a.t1_s} s but segment {k + 1} starts at {b.t0_s} s")
        if np.max(np.abs(a.control_points[-1] - b.control_points[0])) > tol:
            bad.append(f"{n}: position jumps at t = {a.t1_s} s")
        va, vb = a.velocity(a.t1_s)[0], b.velocity(b.t0_s)[0]
        if not any(abs(t - a.t1_s) < tol for t in impact_times) and np.max(np.abs(va - vb)) > tol:
            bad.append(f"{n}: velocity jumps at t = {a.t1_s} s without an impact ({va} -> {vb})")
    if np.max(np.abs(segs[0].control_points[0] - spec.position_m)) > tol:
        bad.append(f"{n}: starts at {segs[0].control_points[0]}, scenario says {spec.position_m}")
    if np.max(np.abs(segs[0].velocity(0.0)[0] - spec.velocity_mps)) > tol:
        bad.append(f"{n}: initial velocity {segs[0].velocity(0.0)[0]}, scenario says {spec.velocity_mps}")
    if spec.final_position_m is not None and np.max(np.abs(segs[-1].control_points[-1] - spec.final_position_m)) > tol:
        bad.append(f"{n}: ends at {segs[-1].control_points[-1]}, scenario says {spec.final_position_m}")
    if spec.final_velocity_mps is not None:
        v_end = segs[-1].velocity(segs[-1].t1_s)[0]
        if np.max(np.abs(v_end - spec.final_velocity_mps)) > tol:
            bad.append(f"{n}: final velocity {v_end}, scenario says {spec.final_velocity_mps}")
    for k, s in enumerate(segs):
        if s.duration_s <= 0:
            bad.append(f"{n}: segment {k} has non-positive duration")
            continue
        if spec.velocity_bound_mps is not None:
            v = np.abs(s.velocity_control_points()).max(axis=0)
            for axis in range(2):
                if v[axis] > spec.velocity_bound_mps[axis] + tol:
                    bad.append(f"{n}: segment {k} velocity {v[axis]:.4f} m/s exceeds the {'xy'[axis]} bound "
                               f"{spec.velocity_bound_mps[axis]} m/s")
        if body.kind == "object":
            if len(s.control_points) > 2 and np.max(np.abs(s.acceleration_control_points())) > tol:
                bad.append(f"{n}: object segment {k} is not a straight constant-velocity flight")
        elif spec.thrust_limit_N is not None and len(s.control_points) > 2:
            force = spec.mass_kg * np.abs(s.acceleration_control_points()).max(axis=0)
            for axis in range(2):
                if force[axis] > spec.thrust_limit_N[axis] * (1 + 1e-9) + tol:
                    bad.append(f"{n}: segment {k} needs {force[axis]:.3f} N along {'xy'[axis]}, more than the "
                               f"{spec.thrust_limit_N[axis]} N thrust limit")
    return bad


def _check_impact(plan: PlanLike, imp: PlannedImpact, scenario: Scenario, tol: float) -> list[str]:
    bad = []
    t = imp.time_s
    label = f"impact {imp.robot}->{imp.object} at t = {t:.3f} s"
    robot, obj = plan.bodies[imp.robot], plan.bodies[imp.object]
    if np.max(np.abs(robot.position(t) - obj.position(t))) > tol:
        bad.append(f"{label}: robot at {robot.position(t)}, object at {obj.position(t)}")
    eps = 1e-9 * max(1.0, t)
    pairs = {
        "robot_velocity_before": (imp.robot_velocity_before, pre_velocity_of(robot, t)),
        "robot_velocity_after": (imp.robot_velocity_after, robot.velocity(t + eps)),
        "object_velocity_before": (imp.object_velocity_before, pre_velocity_of(obj, t)),
        "object_velocity_after": (imp.object_velocity_after, obj.velocity(t + eps)),
    }
    for key, (recorded, actual) in pairs.items():
        if np.max(np.abs(np.asarray(recorded) - actual)) > tol:
            bad.append(f"{label}: recorded {key} {recorded} but the trajectory has {actual}")
    m_r, m_o = scenario.body(imp.robot).mass_kg, scenario.body(imp.object).mass_kg
    vr0, vr1 = np.asarray(imp.robot_velocity_before), np.asarray(imp.robot_velocity_after)
    vo0, vo1 = np.asarray(imp.object_velocity_before), np.asarray(imp.object_velocity_after)
    momentum = m_r * (vr1 - vr0) + m_o * (vo1 - vo0)
    if np.max(np.abs(momentum)) > tol * (m_r + m_o):
        bad.append(f"{label}: momentum not conserved (change {momentum} kg m/s)")
    restitution = (vo1 - vr1) + scenario.restitution * (vo0 - vr0)
    if np.max(np.abs(restitution)) > tol:
        bad.append(f"{label}: restitution law v_O+ - v_R+ = -e (v_O- - v_R-) off by {restitution} m/s")
    return bad


def _check_impact_robustness(plan: PlanLike, scenario: Scenario, tol: float) -> list[str]:
    """An impact-robust plan's funnels and copies (:func:`~planners.plan.funnels.check_impact_robust`); a
    spatially robust plan must carry none."""
    if plan.planner == "ir":
        return check_impact_robust(plan, scenario, tol)
    if plan.delta_mps is not None or plan.funnels or plan.copies:
        return [f"a plan of planner {plan.planner!r} has delta_mps, funnels or copies: only an impact-robust "
                "('ir') plan has them"]
    return []


PLAN_CHECKS: tuple[Callable[[PlanLike, Scenario, float], list[str]], ...] = (
    _check_structure, _check_impact_records, _check_trajectories, _check_impact_laws, _check_impact_robustness,
)
_STRUCTURAL = frozenset({_check_structure, _check_impact_records})
