"""A Plan: per body a chain of Bezier segments in space and time (paper Eq. 11), and the impact events.

Written by the offline planner, followed by the expert controller, drawn by the plotter. Each segment is a
space curve r(s) with control points (degree + 1, 2) and a time curve h(s) = t0 + s (t1 - t0) (degree 1),
so real velocities are dr/dt = r'(s) / (t1 - t0) and accelerations r''(s) / (t1 - t0)^2.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from impact_env.scenario import Scenario
from planners import bezier, plan_schema
from planners.errors import PlanCheckError
from planners.funnels import ImpactCopies, ObjectFunnel, check_impact_robust
from planners.plan_files import read_plan_json, write_plan_json

__all__ = ["BodyPlan", "ImpactCopies", "ObjectFunnel", "Plan", "PlannedImpact", "Segment"]


@dataclass
class Segment:
    """One Bezier piece of a body's trajectory over [t0_s, t1_s]."""

    t0_s: float
    t1_s: float
    control_points: np.ndarray  # (degree + 1, 2), metres

    @property
    def duration_s(self) -> float:
        return self.t1_s - self.t0_s

    def _phase(self, t: np.ndarray) -> np.ndarray:
        return np.minimum(np.maximum((np.asarray(t, dtype=float) - self.t0_s) / self.duration_s, 0.0), 1.0)

    def position(self, t: np.ndarray | float) -> np.ndarray:
        return bezier.evaluate(self.control_points, self._phase(t))

    def velocity(self, t: np.ndarray | float) -> np.ndarray:
        return bezier.evaluate(bezier.derivative(self.control_points), self._phase(t)) / self.duration_s

    def acceleration(self, t: np.ndarray | float) -> np.ndarray:
        dd = bezier.derivative(bezier.derivative(self.control_points))
        return bezier.evaluate(dd, self._phase(t)) / self.duration_s ** 2

    def velocity_control_points(self) -> np.ndarray:
        """Control points of the real velocity dr/dt (m/s): the hull bounds every velocity on the segment."""
        return bezier.derivative(self.control_points) / self.duration_s

    def acceleration_control_points(self) -> np.ndarray:
        return bezier.derivative(bezier.derivative(self.control_points)) / self.duration_s ** 2


@dataclass
class BodyPlan:
    """The planned trajectory of one body: contiguous segments from 0 to tf."""

    name: str
    kind: str  # "robot" or "object"
    segments: list[Segment]

    @property
    def knots_s(self) -> np.ndarray:
        return np.array([s.t0_s for s in self.segments] + [self.segments[-1].t1_s])

    def _index(self, t: np.ndarray) -> np.ndarray:
        # right-continuous: at a knot the later segment is used (post-impact velocity), except at the end
        return np.clip(np.searchsorted(self.knots_s, t, side="right") - 1, 0, len(self.segments) - 1)

    def _sample(self, t: np.ndarray | float, what: str) -> np.ndarray:
        ts = np.atleast_1d(np.asarray(t, dtype=float))
        out = np.empty((len(ts), 2))
        idx = self._index(ts)
        for k in np.unique(idx):
            mask = idx == k
            out[mask] = getattr(self.segments[k], what)(ts[mask])
        return out[0] if np.ndim(t) == 0 else out

    def position(self, t: np.ndarray | float) -> np.ndarray:
        """Position(s) (m) at time(s) t: shape (2,) for a scalar t, (len(t), 2) otherwise."""
        return self._sample(t, "position")

    def velocity(self, t: np.ndarray | float) -> np.ndarray:
        """Velocity (m/s); right-continuous at impacts (the post-impact velocity at the impact time)."""
        return self._sample(t, "velocity")

    def acceleration(self, t: np.ndarray | float) -> np.ndarray:
        return self._sample(t, "acceleration")


@dataclass
class PlannedImpact:
    """A planned robot-object impact, velocities in real units (m/s)."""

    time_s: float
    robot: str
    object: str
    position: tuple[float, float]
    object_velocity_before: tuple[float, float]
    object_velocity_after: tuple[float, float]
    robot_velocity_before: tuple[float, float]
    robot_velocity_after: tuple[float, float]


@dataclass
class Plan:
    """Trajectories of every body and the impacts, with how the plan was obtained.

    ``planner`` is ``"sr"`` (spatially robust: ``robustness`` is the maximised rho) or ``"ir"``
    (impact-robust: ``delta_mps`` is the maximised tolerated post-impact velocity error per axis,
    ``funnels`` the objects' state boxes, ``copies`` the robots' contingency curves per impact, see
    :mod:`planners.funnels`; ``robustness`` is then the nominal curves' sampled STL robustness).
    """

    scenario: str
    planner: str
    robustness: float
    bodies: dict[str, BodyPlan]
    impacts: list[PlannedImpact]
    solver: str = ""
    solve_time_s: float = 0.0
    build_time_s: float = 0.0
    mip_gap: float = 0.0
    stats: dict[str, Any] = field(default_factory=dict)
    delta_mps: float | None = None
    funnels: dict[str, ObjectFunnel] = field(default_factory=dict)
    copies: list[ImpactCopies] = field(default_factory=list)

    @property
    def tf_s(self) -> float:
        return max(b.segments[-1].t1_s for b in self.bodies.values())

    def position(self, name: str, t: np.ndarray | float) -> np.ndarray:
        return self.bodies[name].position(t)

    def velocity(self, name: str, t: np.ndarray | float) -> np.ndarray:
        return self.bodies[name].velocity(t)

    def impacts_of(self, name: str) -> list[PlannedImpact]:
        return [i for i in self.impacts if name in (i.robot, i.object)]

    def fingerprint(self) -> str:
        """A short hash of the plan's curves and impacts, bit for bit (not of its timings or stats): two
        plans with the same fingerprint fly the same."""
        d = self.to_dict()
        return hashlib.sha1(json.dumps([d["impacts"], d["bodies"]], sort_keys=True).encode()).hexdigest()[:12]

    # ------------------------------------------------------------------------------------------ JSON
    def to_dict(self) -> dict[str, Any]:
        out = self._base_dict()
        if self.planner == "ir":
            out["delta_mps"] = self.delta_mps
            out["funnels"] = {name: f.to_dict() for name, f in self.funnels.items()}
            out["copies"] = [c.to_dict() for c in self.copies]
        return out

    def _base_dict(self) -> dict[str, Any]:
        return {
            "scenario": self.scenario, "planner": self.planner, "robustness": self.robustness,
            "solve_time_s": self.solve_time_s, "build_time_s": self.build_time_s, "mip_gap": self.mip_gap,
            "solver": self.solver, "stats": self.stats,
            "impacts": [{**asdict(i), "time": i.time_s} for i in self.impacts],
            "bodies": {
                name: {"kind": b.kind, "segments": [
                    {"t0_s": s.t0_s, "t1_s": s.t1_s, "time_control_points": [s.t0_s, s.t1_s],
                     "control_points": np.asarray(s.control_points).tolist()} for s in b.segments]}
                for name, b in self.bodies.items()
            },
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Plan:
        """Build a plan from its JSON form, every field checked (:mod:`planners.plan_schema`).

        Raises:
            PlanCheckError: listing every missing, unknown or malformed field by its path, e.g.
                ``bodies.R1.segments[3].control_points[2][0] must be a finite number ...``.
        """
        problems: list[str] = []
        fields = plan_schema.read(data, plan_schema.PLAN_FIELDS, "", problems)
        if fields is plan_schema.INVALID:
            raise PlanCheckError(problems)
        bodies = {}
        for name, b in fields["bodies"].items():
            segments = []
            for k, seg in enumerate(b["segments"]):
                pair = seg["time_control_points"]
                if pair is not None and pair != (seg["t0_s"], seg["t1_s"]):
                    problems.append(f"bodies.{name}.segments[{k}].time_control_points = {list(pair)} must be "
                                    f"[t0_s, t1_s] = {[seg['t0_s'], seg['t1_s']]}")
                segments.append(Segment(seg["t0_s"], seg["t1_s"], seg["control_points"]))
            bodies[name] = BodyPlan(name, b["kind"], segments)
        impacts = []
        for k, i in enumerate(fields["impacts"]):
            if i["time"] is not None and i["time"] != i["time_s"]:
                problems.append(f"impacts[{k}].time = {i['time']} differs from impacts[{k}].time_s = {i['time_s']}")
            impacts.append(PlannedImpact(
                time_s=i["time_s"], robot=i["robot"], object=i["object"], position=i["position"],
                object_velocity_before=i["object_velocity_before"], object_velocity_after=i["object_velocity_after"],
                robot_velocity_before=i["robot_velocity_before"], robot_velocity_after=i["robot_velocity_after"]))
        funnels = {name: ObjectFunnel(name, f["t0_s"], f["dt_s"], f["position_halfwidth_m"],
                                      f["velocity_halfwidth_mps"], f["final_box_m"], f["final_box_mps"])
                   for name, f in fields["funnels"].items()}
        copies = [ImpactCopies(c["time_s"], c["robot"], c["object"], c["window_start_s"], c["window_end_s"],
                               c["signs"], c["before"], c["after"]) for c in fields["copies"]]
        if problems:
            raise PlanCheckError(problems)
        return cls(fields["scenario"], fields["planner"], fields["robustness"], bodies, impacts, fields["solver"],
                   fields["solve_time_s"], fields["build_time_s"], fields["mip_gap"], fields["stats"],
                   fields["delta_mps"], funnels, copies)

    def save(self, path: str | Path) -> Path:
        return write_plan_json(path, self.to_dict(), indent=1)

    @classmethod
    def load(cls, path: str | Path) -> Plan:
        """Read a plan file written by :meth:`save`; any problem is a :class:`PlanCheckError` naming it."""
        return cls.from_dict(read_plan_json(path, lambda message: PlanCheckError([message])))

    # ----------------------------------------------------------------------------------------- check
    def check(self, scenario: Scenario, tol: float = 1e-6) -> None:
        """Verify the plan against the scenario; raise :class:`PlanCheckError` listing every violation.

        Checks (:data:`PLAN_CHECKS`, in order): the plan has exactly the scenario's bodies, each with its kind,
        and finite segments of shape (degree + 1, 2); every impact names a robot and an object of the
        scenario at a time in [0, tf] with finite 2-D numbers, and none is listed twice; then contiguous
        segments covering [0, tf]; position continuity; initial and final states;
        per-axis velocity bounds and thrust limits (m * |acceleration| <= thrust_limit_N per axis, with the
        robot's heading held, so body axes are world axes) on the hull of the derivative control points,
        which bounds every point of the curve; objects move in straight lines at constant velocity between
        impacts; velocities are continuous where there is no impact; at each impact the positions coincide
        and the point-mass law (Eq. 5) holds in REAL velocities: momentum is conserved and the normal
        relative velocity is reversed and scaled by e. An impact-robust plan (``planner == "ir"``) also has
        its funnels and copies checked (:func:`planners.funnels.check_impact_robust`): every copy's contact
        and impact law at its box vertex, limits, sharing and affine feedback, and the box propagation.
        """
        bad: list[str] = []
        for check in PLAN_CHECKS:
            bad += check(self, scenario, tol)
            if bad and check in _STRUCTURAL:  # later checks index bodies and segments that must exist
                break
        if bad:
            raise PlanCheckError(bad)

    def _impact_times(self, name: str) -> list[float]:
        return [i.time_s for i in self.impacts_of(name)]


def _check_structure(plan: Plan, scenario: Scenario, tol: float) -> list[str]:
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
            if cp.ndim != 2 or cp.shape[1] != 2 or not 2 <= len(cp) <= plan_schema.MAX_DEGREE + 1:
                bad.append(f"{name}: segment {k} control points have shape {cp.shape}, need (degree + 1, 2) with "
                           f"degree 1..{plan_schema.MAX_DEGREE}")
            elif not np.all(np.isfinite(cp.astype(float))):
                bad.append(f"{name}: segment {k} has non-finite control points")
            if not (math.isfinite(seg.t0_s) and math.isfinite(seg.t1_s)):
                bad.append(f"{name}: segment {k} has non-finite times [{seg.t0_s}, {seg.t1_s}]")
    return bad


def _check_impact_records(plan: Plan, scenario: Scenario, tol: float) -> list[str]:
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


def _check_trajectories(plan: Plan, scenario: Scenario, tol: float) -> list[str]:
    bad = []
    for spec in scenario.bodies:
        bad += _check_body(plan.bodies[spec.name], spec, scenario.tf_s, plan._impact_times(spec.name), tol)
    return bad


def _check_impact_laws(plan: Plan, scenario: Scenario, tol: float) -> list[str]:
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


def _check_impact(plan: Plan, imp: PlannedImpact, scenario: Scenario, tol: float) -> list[str]:
    bad = []
    t = imp.time_s
    label = f"impact {imp.robot}->{imp.object} at t = {t:.3f} s"
    robot, obj = plan.bodies[imp.robot], plan.bodies[imp.object]
    if np.max(np.abs(robot.position(t) - obj.position(t))) > tol:
        bad.append(f"{label}: robot at {robot.position(t)}, object at {obj.position(t)}")
    eps = 1e-9 * max(1.0, t)
    pairs = {
        "robot_velocity_before": (imp.robot_velocity_before, _left_velocity(robot, t)),
        "robot_velocity_after": (imp.robot_velocity_after, robot.velocity(t + eps)),
        "object_velocity_before": (imp.object_velocity_before, _left_velocity(obj, t)),
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


def _left_velocity(body: BodyPlan, t: float) -> np.ndarray:
    """Velocity just before t (the segment that ends at t)."""
    for s in body.segments:
        if s.t0_s < t <= s.t1_s + 1e-12:
            return s.velocity(s.t1_s)[0] if abs(s.t1_s - t) < 1e-9 else s.velocity(t)[0]
    return body.segments[0].velocity(t)[0]


# What Plan.check verifies, in order. The structural checks come first: when one fails, the later ones (which
# index bodies and evaluate curves) are skipped. A new plan feature adds its check here.
def _check_impact_robustness(plan: Plan, scenario: Scenario, tol: float) -> list[str]:
    """An impact-robust plan's funnels and copies (:func:`planners.funnels.check_impact_robust`); a spatially
    robust plan must carry none."""
    if plan.planner == "ir":
        return check_impact_robust(plan, scenario, tol)
    if plan.delta_mps is not None or plan.funnels or plan.copies:
        return [f"a plan of planner {plan.planner!r} has delta_mps, funnels or copies: only an impact-robust "
                "('ir') plan has them"]
    return []


PLAN_CHECKS: tuple[Callable[[Plan, Scenario, float], list[str]], ...] = (
    _check_structure, _check_impact_records, _check_trajectories, _check_impact_laws, _check_impact_robustness,
)
_STRUCTURAL = frozenset({_check_structure, _check_impact_records})
