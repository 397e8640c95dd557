"""The parts of a plan: Bezier segments, a body's trajectory, planned impacts, and what an impact-robust plan adds.

Each segment is a space curve r(s) with control points (degree + 1, 2) and a time curve
h(s) = t0 + s (t1 - t0) (degree 1), so real velocities are dr/dt = r'(s) / (t1 - t0) and accelerations
r''(s) / (t1 - t0)^2 (paper Eq. 11). An impact-robust plan adds, per object, an :class:`ObjectFunnel` (its
state box on the plan's time grid) and, per impact, the robot's :class:`ImpactCopies` (Lemma 1's
contingency curves); :mod:`planners.plan.funnels` holds their maths.

:class:`PlanLike` is what the checks and the funnel maths read of a :class:`~planners.plan.Plan`: the plan
class sits above them (it calls them), so they name what they read rather than import it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from planners import bezier

__all__ = ["BodyPlan", "ImpactCopies", "ObjectFunnel", "PlanLike", "PlannedImpact", "Segment"]


@dataclass
class Segment:
    """One Bezier piece of a body's trajectory over [t0_s, t1_s]."""

    t0_s: float
    t1_s: float
    control_points: np.ndarray  # (degree + 1, 2), metres

    @property
    def duration_s(self) -> float:
        return self.t1_s - self.t0_s

    def _phase(self, t: np.ndarray | float) -> np.ndarray:
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
class ObjectFunnel:
    """The object's state box on the grid t_k = t0_s + k dt_s, k = 0..N, around its nominal plan.

    position_halfwidth_m: (N + 1, 2), per knot and axis. velocity_halfwidth_mps: (N, 2), per interval and
    axis (the velocity is constant on an interval). final_box_m / final_box_mps: the half-widths the final
    state must stay within (the scenario's ``[final_box]``): the residual velocity the task tolerates.
    """

    object: str
    t0_s: float
    dt_s: float
    position_halfwidth_m: np.ndarray
    velocity_halfwidth_mps: np.ndarray
    final_box_m: tuple[float, float]
    final_box_mps: tuple[float, float]

    @property
    def intervals(self) -> int:
        return len(self.velocity_halfwidth_mps)

    @property
    def knots_s(self) -> np.ndarray:
        return self.t0_s + self.dt_s * np.arange(self.intervals + 1)

    @property
    def terminal_velocity_halfwidth_mps(self) -> np.ndarray:
        """The planned final velocity spread (<= ``final_box_mps``): the residual the plan accounts for."""
        return np.asarray(self.velocity_halfwidth_mps[-1])

    def position_halfwidth(self, t: np.ndarray | float) -> np.ndarray:
        """Position half-widths at time(s) t, linear between knots: a bound, since a zonotope's half-width
        sum |g_p + tau g_v| is convex in the flight time tau."""
        t = np.asarray(t, dtype=float)
        knots = self.knots_s
        return np.stack([np.interp(t, knots, self.position_halfwidth_m[:, a]) for a in range(2)], axis=-1)

    def velocity_halfwidth(self, t: np.ndarray | float) -> np.ndarray:
        """Velocity half-widths at time(s) t (right-continuous at knots, like the plan's velocities)."""
        t = np.asarray(t, dtype=float)
        k = np.clip(np.floor((t - self.t0_s) / self.dt_s + 1e-9).astype(int), 0, self.intervals - 1)
        return np.asarray(self.velocity_halfwidth_mps)[k]

    def to_dict(self) -> dict[str, Any]:
        return {"t0_s": self.t0_s, "dt_s": self.dt_s,
                "position_halfwidth_m": np.asarray(self.position_halfwidth_m).tolist(),
                "velocity_halfwidth_mps": np.asarray(self.velocity_halfwidth_mps).tolist(),
                "final_box_m": list(self.final_box_m), "final_box_mps": list(self.final_box_mps)}

    @classmethod
    def from_dict(cls, name: str, d: dict[str, Any]) -> ObjectFunnel:
        return cls(name, float(d["t0_s"]), float(d["dt_s"]), np.array(d["position_halfwidth_m"], dtype=float),
                   np.array(d["velocity_halfwidth_mps"], dtype=float), _pair(d["final_box_m"]),
                   _pair(d["final_box_mps"]))


def _pair(values: Any) -> tuple[float, float]:
    x, y = values
    return float(x), float(y)


@dataclass
class ImpactCopies:
    """The four copies of ``robot``'s curve around its impact with ``object`` at ``time_s``.

    The copies may differ on a window of grid intervals: ``before[j]`` (shape (W_before, degree + 1, 2)) are
    copy j's control points on the intervals that end at the impact, from ``window_start_s``; ``after[j]``
    (W_after, degree + 1, 2) those on the intervals that start at it, to ``window_end_s``. signs[j]:
    (s_p, s_v), the box vertex copy j meets on each axis. Outside the window the copies are the nominal curve.
    """

    time_s: float
    robot: str
    object: str
    window_start_s: float
    window_end_s: float
    signs: list[tuple[int, int]]
    before: list[np.ndarray]
    after: list[np.ndarray]

    def weights(self, xi: np.ndarray) -> np.ndarray:
        """Blend weights (4, 2) per copy and axis for the object's normalised pre-impact box coordinates
        ``xi`` = [[xi_p_x, xi_v_x], [xi_p_y, xi_v_y]] (multilinear; clipped to [-1, 1])."""
        xi = np.clip(np.asarray(xi, dtype=float).reshape(2, 2), -1.0, 1.0)
        s = np.asarray(self.signs, dtype=float)  # (4, 2): s_p, s_v
        return np.stack([(1 + s[:, 0] * xi[a, 0]) * (1 + s[:, 1] * xi[a, 1]) / 4.0 for a in range(2)], axis=1)

    def blend(self, xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Control points (before, after), shapes as one copy's, of the blend for box coordinates ``xi``."""
        w = self.weights(xi)
        out = []
        for part in (np.asarray(self.before), np.asarray(self.after)):  # (4, W, d + 1, 2)
            out.append(np.stack([np.einsum("j,jsk->sk", w[:, a], part[..., a]) for a in range(2)], axis=-1))
        return out[0], out[1]

    def to_dict(self) -> dict[str, Any]:
        return {"time_s": self.time_s, "robot": self.robot, "object": self.object,
                "window_start_s": self.window_start_s, "window_end_s": self.window_end_s,
                "signs": [list(s) for s in self.signs],
                "before": [np.asarray(b).tolist() for b in self.before],
                "after": [np.asarray(a).tolist() for a in self.after]}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ImpactCopies:
        return cls(float(d["time_s"]), str(d["robot"]), str(d["object"]), float(d["window_start_s"]),
                   float(d["window_end_s"]), [(int(sp), int(sv)) for sp, sv in d["signs"]],
                   [np.array(b, dtype=float) for b in d["before"]], [np.array(a, dtype=float) for a in d["after"]])


class PlanLike(Protocol):
    """What :mod:`planners.plan.checks` and :mod:`planners.plan.funnels` read of a plan."""

    planner: str
    bodies: dict[str, BodyPlan]
    impacts: list[PlannedImpact]
    delta_mps: float | None
    funnels: dict[str, ObjectFunnel]
    copies: list[ImpactCopies]
