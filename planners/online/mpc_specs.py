"""Configuration, inputs and outputs of the impact-aware MPC (the controller is planners/online/mpc.py)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from impact_env.config_checks import check_choice, check_integer, check_number, check_value
from planners.errors import MPCInputError

SOLVERS = ("sqp", "fatrop", "ipopt")
NX, NU = 6, 3  # state [px, py, theta, vx, vy, omega], input [Fx, Fy, tau]
_NSI = 8  # impact slacks per node: (p, v) positive and negative parts; plus one per keep-off row
_WEIGHTS = ("q_pos", "q_vel", "q_heading", "q_omega", "r_input", "terminal_factor")


@dataclass(frozen=True)
class MPCConfig:
    """Options of the impact-aware MPC. Structure (horizon, dt, solver) is fixed at construction; the weights
    can change via :meth:`FreeflyerMPC.update_weights <planners.online.mpc.FreeflyerMPC.update_weights>`."""

    horizon: int = 10
    """Nodes N of the horizon (node 0 is the measured state)."""
    dt_s: float = 0.1
    """Time between nodes (s): the control period."""
    q_pos: float = 100.0
    """Weight of the position error (1/m^2)."""
    q_vel: float = 10.0
    """Weight of the velocity error (s^2/m^2)."""
    q_heading: float = 100.0
    """Weight of the heading error (1/rad^2)."""
    q_omega: float = 10.0
    """Weight of the angular velocity (s^2/rad^2)."""
    r_input: float = 0.1
    """Weight of the inputs, per (input / limit)^2."""
    terminal_factor: float = 10.0
    """The last node's state weights are this many times the others' (dimensionless)."""
    thrust_fraction: float = 1.0
    """Share of the body's thrust and torque limits the inputs may use (in (0, 1])."""
    impact_penalty: float = 3e3
    """Exact L1 penalty per m or m/s of impact-state violation."""
    avoid_penalty: float = 3e3
    """Penalty per m of keep-off violation (linear and quadratic)."""
    solver: str = "sqp"
    """The NLP solver: ``sqp`` (CasADi sqpmethod + qrqp), ``fatrop`` or ``ipopt``."""
    fallback_solver: str | None = "ipopt"
    """Retries a solve the primary ``solver`` failed; None: no retry."""
    sqp_max_iter: int = 30
    """Iterations of the ``sqp`` solver (converged solves take <= 27 in ``benchmarks/mpc.py`` and the keep-off
    stress cases, so a solve that needs more is handed to the fallback early); fatrop and ipopt get 100."""
    keep_off_rows: int = 1
    """Keep-off constraints (:class:`AvoidSpec` discs or :class:`HalfPlaneSpec` half-planes) one solve can
    take, each with its own slack per node (the expert uses one for the nearest object, one per other robot,
    and one for the nearest wall or obstacle face)."""

    def __post_init__(self) -> None:
        check_integer(self, "horizon", MPCInputError, low=2)
        for name in ("dt_s", "impact_penalty", "avoid_penalty"):
            check_number(self, name, MPCInputError, low=0, low_open=True)
        for name in _WEIGHTS:
            check_number(self, name, MPCInputError, low=0)
        check_number(self, "thrust_fraction", MPCInputError, low=0, high=1, low_open=True)
        check_choice(self, "solver", MPCInputError, SOLVERS)
        check_choice(self, "fallback_solver", MPCInputError, SOLVERS, none="no retry")
        check_integer(self, "sqp_max_iter", MPCInputError, low=1)
        check_integer(self, "keep_off_rows", MPCInputError, low=1)


def _vector(value: object, shape: tuple[int, ...], name: str) -> np.ndarray:
    """``value`` as a finite float array of ``shape``, or MPCInputError naming ``name``."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise MPCInputError(f"{name} must be numbers of shape {shape}, got {value!r}") from None
    if arr.shape != shape:
        raise MPCInputError(f"{name} must have shape {shape}, got {arr.shape}")
    if not np.isfinite(arr).all():
        raise MPCInputError(f"{name} contains NaN or infinite values: {arr.tolist()}")
    return arr


@dataclass
class ImpactSpec:
    """A planned impact at horizon node ``step`` (0..N, i.e. at t + step * dt_s).

    ``position`` (2,) m and ``velocity_before`` (2,) m/s: the robot's planned pre-impact state, enforced at
    that node; ``velocity_after`` (2,) m/s: its planned post-impact velocity, from which the prediction
    continues after the node. ``step = 0`` means "the impact happens at the start of the coming control
    period" (contact due now, not yet in the measured state): node 0 is the measurement, so nothing is
    enforced there and only the velocity jump applies; the wrench is then chosen for the post-impact motion.
    """

    step: int
    position: np.ndarray
    velocity_before: np.ndarray
    velocity_after: np.ndarray

    def __post_init__(self) -> None:
        if isinstance(self.step, bool) or not isinstance(self.step, (int, np.integer)):
            raise MPCInputError(f"ImpactSpec.step must be an integer node index, got {self.step!r}")
        self.step = int(self.step)
        for name in ("position", "velocity_before", "velocity_after"):
            setattr(self, name, _vector(getattr(self, name), (2,), f"ImpactSpec.{name}"))


@dataclass
class AvoidSpec:
    """Keep-off constraint: ``|p_k - centers[k]| >= min_distance`` (m) at the nodes where ``active[k]``.

    ``centers`` (N+1, 2) m: predicted centre of the body to avoid at each node; ``active`` (N+1,) bool;
    ``min_distance``: centre to centre, so the two radii plus a margin. Node 0 (the measured state) is never
    constrained. Deactivate the nodes around a planned impact with the same body: there the impact position
    (radii apart) contradicts the keep-off distance and the two soft constraints would meet half-way.
    """

    centers: np.ndarray
    min_distance: float
    active: np.ndarray

    def __post_init__(self) -> None:
        check_value("AvoidSpec.min_distance", self.min_distance, MPCInputError, low=0, low_open=True)
        self.min_distance = float(self.min_distance)
        self.active = np.asarray(self.active, dtype=bool)

    def check(self, horizon: int) -> None:
        self.centers = _vector(self.centers, (horizon + 1, 2), "AvoidSpec.centers")
        if self.active.shape != (horizon + 1,):
            raise MPCInputError(f"AvoidSpec.active must have shape {(horizon + 1,)}, got {self.active.shape}")

    def clearance(self, positions: np.ndarray) -> float:
        """min over active nodes 1..N of |p_k - c_k| - min_distance (m)."""
        d = positions - self.centers
        return float(np.hypot(d[:, 0], d[:, 1])[1:][self.active[1:]].min() - self.min_distance)


@dataclass
class HalfPlaneSpec:
    """Keep-out of a half-plane: ``normals[k] . p_k >= offsets[k]`` (m) at the nodes where ``active[k]``.

    For a wall or an obstacle face: the face's outward unit normal and its offset plus the robot's radius
    (and a margin). ``normals`` (2,) or (N+1, 2), unit; ``offsets`` a number or (N+1,); ``active`` (N+1,) bool.
    A fixed half-plane is already linear, so nothing is re-linearised.
    """

    normals: np.ndarray
    offsets: np.ndarray | float
    active: np.ndarray

    def check(self, horizon: int) -> None:
        shape = (horizon + 1,)
        normals = np.asarray(self.normals, dtype=float)
        one = normals.shape == (2,)  # one normal for every node (a wall): checked once, then repeated
        normals = _vector(normals, (2,) if one else (horizon + 1, 2), "HalfPlaneSpec.normals")
        flat = normals.reshape(-1, 2)
        if (np.abs(np.hypot(flat[:, 0], flat[:, 1]) - 1.0) > 1e-6).any():
            raise MPCInputError("HalfPlaneSpec.normals must be unit vectors")
        self.normals = np.tile(normals, (horizon + 1, 1)) if one else normals
        offsets = np.asarray(self.offsets, dtype=float)
        if offsets.shape == ():
            offsets = np.full(shape, float(offsets))
        self.offsets = _vector(offsets, shape, "HalfPlaneSpec.offsets")
        self.active = np.asarray(self.active, dtype=bool)
        if self.active.shape != shape:
            raise MPCInputError(f"HalfPlaneSpec.active must have shape {shape}, got {self.active.shape}")

    def clearance(self, positions: np.ndarray) -> float:
        """min over active nodes 1..N of normal . p - offset (m)."""
        gap = np.einsum("kd,kd->k", self.normals, positions) - self.offsets
        return float(gap[1:][self.active[1:]].min())


@dataclass
class MPCResult:
    """One solve. ``wrench`` (3,): body-frame [Fx, Fy, tau] (N, N m) to apply now, within bounds, never NaN.

    ``predicted`` (N+1, 6): predicted states at nodes 0..N (node 0 = measured state); ``inputs`` (N, 3):
    the planned wrenches; ``impact_error``: max |predicted - planned| pre-impact [p, v] at the impact node
    (m or m/s; 0 without impact or at step 0); ``min_clearance_m``: min over active keep-off nodes of distance minus
    min_distance (inf without); ``solver``: which solver produced the result.
    """

    wrench: np.ndarray
    success: bool
    solve_ms: float
    predicted: np.ndarray
    inputs: np.ndarray = field(default_factory=lambda: np.zeros((0, NU)))
    status: str = ""
    iterations: int = 0
    solver: str = ""
    impact_error: float = 0.0
    min_clearance_m: float = math.inf
