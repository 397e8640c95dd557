"""A Plan: per body a chain of Bezier segments in space and time (paper Eq. 11), and the impact events.

Written by the offline planner, followed by the expert controller, drawn by the plotter. Its parts are in
:mod:`planners.plan.types`; its file is JSON (:mod:`planners.plan.schema` reads it field by field,
:mod:`planners.plan.files` between a path and JSON), and :mod:`planners.plan.checks` verifies it against the
scenario.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

import planners.plan.schema as schema
from planners.errors import PlanCheckError
from planners.plan.checks import check_plan
from planners.plan.files import read_plan_json, write_plan_json
from planners.plan.types import BodyPlan, ImpactCopies, ObjectFunnel, PlannedImpact, Segment

if TYPE_CHECKING:
    from impact_env.transport.scenario import Scenario

__all__ = ["Plan"]


@dataclass
class Plan:
    """Trajectories of every body and the impacts, with how the plan was obtained.

    ``planner`` is ``"sr"`` (spatially robust: ``robustness`` is the maximised rho) or ``"ir"``
    (impact-robust: ``delta_mps`` is the maximised tolerated post-impact velocity error per axis,
    ``funnels`` the objects' state boxes, ``copies`` the robots' contingency curves per impact, see
    :mod:`planners.plan.funnels`; ``robustness`` is then the nominal curves' sampled STL robustness).
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
        """Build a plan from its JSON form, every field checked (:mod:`planners.plan.schema`).

        Raises:
            PlanCheckError: listing every missing, unknown or malformed field by its path, e.g.
                ``bodies.R1.segments[3].control_points[2][0] must be a finite number ...``.
        """
        problems: list[str] = []
        fields = schema.read(data, schema.PLAN_FIELDS, "", problems)
        if fields is schema.INVALID:
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
        data = read_plan_json(path, lambda message: PlanCheckError([message]))
        try:
            return cls.from_dict(data)
        except PlanCheckError as exc:
            raise PlanCheckError(exc.violations, source=str(path)) from None

    # ----------------------------------------------------------------------------------------- check
    def check(self, scenario: Scenario, tol: float = 1e-6) -> None:
        """Verify the plan against the scenario; raise :class:`PlanCheckError` listing every violation.

        Checks (:data:`planners.plan.checks.PLAN_CHECKS`, in order): the plan has exactly the scenario's bodies,
        each with its kind, and finite segments of shape (degree + 1, 2); every impact names a robot and an
        object of the scenario at a time in [0, tf] with finite 2-D numbers, and none is listed twice; then
        contiguous segments covering [0, tf]; position continuity; initial and final states; per-axis
        velocity bounds and thrust limits (m * |acceleration| <= thrust_limit_N per axis, with the robot's
        heading held, so body axes are world axes) on the hull of the derivative control points, which
        bounds every point of the curve; objects move in straight lines at constant velocity between
        impacts; velocities are continuous where there is no impact; at each impact the positions coincide
        and the point-mass law (Eq. 5) holds in REAL velocities: momentum is conserved and the normal
        relative velocity is reversed and scaled by e. An impact-robust plan (``planner == "ir"``) also has
        its funnels and copies checked (:func:`planners.plan.funnels.check_impact_robust`): every copy's
        contact and impact law at its box vertex, limits, sharing and affine feedback, and the box
        propagation.
        """
        check_plan(self, scenario, tol)

