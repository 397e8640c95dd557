"""The bounded QP of one replanned segment (the replanner's, :mod:`planners.online.replanner`).

A segment joins two fixed end states, ``(p0, v0)`` at ``t0`` and ``(p1, v1)`` at ``t1``, and minimises the
integral of |r''|^2 (Eq. 29's acceleration cost). Without bounds the minimiser is the cubic Hermite curve
(:func:`hermite`, closed form). With bounds it is a convex QP over degree-10 Bezier control points (bounding
control points is conservative; the hull tightens with the degree): velocity bounds (Eq. 25), acceleration
bounds (the thrust limits) and the :class:`SegmentLimits` ("safe segments": the world box, obstacle faces,
and at sample times the half-plane off another robot's disc, :func:`separation_rows`; and, for a segment that
must get round the object it ends in contact with, the tangent half-planes of a :class:`WayRound`).

The QP is built ONCE per degree as a CasADi ``conic`` (DAQP, dense) with a fixed sparsity; each call only
fills numbers with numpy. DAQP's "solved" is checked, not trusted: an answer that moves the fixed end states
(DAQP's answer to some infeasible QPs) is no answer (:meth:`_SegmentQP.answer_holds`). More:
``docs/expert_design.md#segment-qp``.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import lru_cache

import casadi as ca
import numpy as np

from planners import bezier
from planners.online.segment_feasibility import FEASIBILITY_TOL
from planners.plan import Segment
from planners.plan.approach import way_blocked

DEGREE = 10
MAX_HALF_PLANES = 4  # obstacle faces (or other fixed half-planes) per segment
SEPARATION_SAMPLES = 8  # sample times of the robot-robot separation rows


@dataclass(frozen=True)
class WayRound:
    """The way round a moving disc to a contact on it: the object a pre-impact segment ends in contact with,
    when the straight way from the robot to its contact point crosses the object's disc (a robot on the far side
    of the object, e.g. after pushing another object; the test of :mod:`planners.plan.approach`).

    A point robot flies through the object; a disc robot that follows such a segment meets the object on its way
    (one_robot_two_objects at 0.02 m/s, seed 23: R1 touched O1 2.5 s before its planned push and then pushed it
    from the wrong side). The rows keep the robot's centre beyond the disc's tangent at a bearing that turns, in
    step with the segment's phase, from the robot's bearing at the start to the contact's bearing at the end, the
    short way round: at each separation sample s_k (phase), with bearing b_k = b0 + s_k (b1 - b0) and
    n_k = (cos b_k, sin b_k), ``n_k . p(s_k) >= n_k . c(t_k) + distance_m``. Each row is linear in the control
    points, so the segment stays a convex QP; the turning schedule is one choice among the ways round (the
    robot may go wider or wait, but not cut through).

    ``centre(t)``: the object's centre at times ``t`` ((N,) -> (N, 2), its free flight); ``distance_m``: r_R + r_O;
    ``bearing0`` and ``bearing1`` (rad): the robot's bearing from the object at the segment's start, and the
    contact's at its end, unwrapped so that ``bearing1 - bearing0`` is the turn (at most pi either way)."""

    centre: Callable[[np.ndarray], np.ndarray]
    distance_m: float
    bearing0: float
    bearing1: float

    @classmethod
    def between(cls, robot_position, contact_position, centre: Callable[[np.ndarray], np.ndarray], t0: float,
                t1: float, distance_m: float) -> WayRound | None:
        """The way round from the robot at ``robot_position`` (time ``t0``) to ``contact_position`` (``t1``); None
        when the straight way there stays outside the disc, in the object's frame (the approach test's criterion,
        :func:`planners.plan.approach.way_blocked`)."""
        c0, c1 = centre(np.array([t0, t1]))
        r0, r1 = np.subtract(robot_position, c0), np.subtract(contact_position, c1)
        if not way_blocked(r0, r1, distance_m):
            return None
        b0 = math.atan2(r0[1], r0[0])
        turn = math.remainder(math.atan2(r1[1], r1[0]) - b0, 2 * math.pi)  # the short way, in [-pi, pi]
        return cls(centre, float(distance_m), b0, b0 + turn)

    def rows(self, t0: float, t1: float) -> list[tuple[float, np.ndarray, float]]:
        """(phase, normal, offset) of the tangent rows at the separation samples of a segment from t0 to t1."""
        s = _SAMPLE_PHASES
        centres = np.asarray(self.centre(t0 + s * (t1 - t0)), float)
        bearings = self.bearing0 + s * (self.bearing1 - self.bearing0)
        normals = np.column_stack([np.cos(bearings), np.sin(bearings)])
        return [(float(s[k]), normals[k], float(normals[k] @ centres[k] + self.distance_m)) for k in range(len(s))]


@dataclass
class SegmentLimits:
    """What a replanned segment must respect besides its end states (all optional).

    ``box``: (xmin, xmax, ymin, ymax) the robot's centre stays in (the world box shrunk by its radius);
    ``half_planes``: (normal (2,), offset) pairs, each asking ``normal . p >= offset`` of the centre;
    ``others``: callables ``t -> (N, 2)`` positions of other robots' centres, to keep at least
    ``separation_m`` (centre to centre) away from; ``way_round``: the object to get round to the contact the
    segment ends in (:class:`WayRound`; only a pre-impact segment has one).
    """

    box: tuple[float, float, float, float] | None = None
    half_planes: list[tuple[np.ndarray, float]] = field(default_factory=list)
    others: list = field(default_factory=list)
    separation_m: float = 0.0
    way_round: WayRound | None = None


def hermite(p0, v0, p1, v1, t0: float, t1: float) -> Segment:
    """Cubic Bezier with the given end positions and velocities: the minimum of the integral of |r''|^2."""
    p0, v0, p1, v1 = (np.asarray(a, float) for a in (p0, v0, p1, v1))
    T = t1 - t0
    return Segment(t0, t1, np.array([p0, p0 + v0 * T / 3.0, p1 - v1 * T / 3.0, p1]))


_SAMPLE_PHASES = np.linspace(0.0, 1.0, SEPARATION_SAMPLES + 2)[1:-1]  # the ends are fixed states, not choices
_SAMPLE_PHASES.flags.writeable = False


def separation_rows(segment: Segment, limits: SegmentLimits) -> list[tuple[float, np.ndarray, float]]:
    """(phase, normal, offset) of the separation rows that the segment comes close to breaking.

    Linearised about ``segment``: at each sample where it comes within the separation (plus 5 cm) of another
    robot's centre q, the row ``normal . p >= normal . q + separation`` keeps this robot beside q, on the
    side it already passes: the normal is the part of (p - q) across the relative motion (a normal along
    the motion would ask it to stop short at one sample and be past at the next). A head-on pass picks the
    left-hand side. A :class:`WayRound`'s rows follow (all of its samples: they are its schedule, not
    linearised); the QP takes the first ``SEPARATION_SAMPLES``.
    """
    rows = _robot_rows(segment, limits)
    if limits.way_round is not None:
        rows += limits.way_round.rows(segment.t0_s, segment.t1_s)
    return rows


def _robot_rows(segment: Segment, limits: SegmentLimits) -> list[tuple[float, np.ndarray, float]]:
    """The rows off other robots' discs (see :func:`separation_rows`)."""
    if not limits.others or limits.separation_m <= 0:
        return []
    s = _SAMPLE_PHASES
    times = segment.t0_s + s * segment.duration_s
    mine = segment.position(times)
    chord = segment.control_points[-1] - segment.control_points[0]
    rows = []
    for other in limits.others:
        q = np.asarray(other(times), float)
        d = mine - q
        close = np.hypot(d[:, 0], d[:, 1]) < limits.separation_m + 0.05
        if not close.any():
            continue
        near = np.flatnonzero(close)
        motion = np.gradient(d, axis=0) if len(d) > 1 else np.tile(chord, (len(d), 1))
        for k in near:
            u = motion[k] if np.hypot(*motion[k]) > 1e-9 else chord
            size = float(np.hypot(*u))
            u = u / size if size > 1e-12 else np.array([1.0, 0.0])
            lateral = d[k] - (d[k] @ u) * u
            if np.hypot(*lateral) < 1e-6:
                lateral = np.array([-u[1], u[0]])
            n = lateral / np.hypot(*lateral)
            rows.append((float(s[k]), n, float(n @ q[k] + limits.separation_m)))
    return rows


# Tikhonov weight toward the straight line: makes the Hessian definite (DAQP factorises it). At 1e-8 the
# condition number (1e9) let DAQP report optimal with bounds broken by 0.5 mm; at 1e-6 they hold to 1e-12
# and the optimum moves by under 1 um.
_REG = 1e-6
FIXED_TOL_M = 1e-9  # how far an accepted answer may move a bounded control point (the fixed ones: not at all)
ROW_TOL = FEASIBILITY_TOL  # m/s, m/s^2 or m: how far an accepted answer may break a row's bound


class _SegmentQP:
    """The QP of one segment, built once per degree (:func:`_qp`).

    Variables are the control points ``[x_0..x_d, y_0..y_d]``; the end positions and velocities fix the
    first two and last two control points of each axis (through their bounds). Rows: the velocity and the
    acceleration control points (sparse), then ``MAX_HALF_PLANES`` half-plane blocks of d+1 rows and
    ``SEPARATION_SAMPLES`` separation rows (dense). DAQP (a dual active-set method for small dense QPs,
    bundled with CasADi) solves it in about 25 us. It is called through CasADi's zero-copy buffer
    (``Function.buffer``): the numbers are written into numpy arrays bound to it once, where
    ``solver(h=..., a=...)`` with numpy arguments spent 0.2 ms converting them to CasADi matrices and back,
    8 times the solve. One buffer per thread (a buffer is one set of arrays).
    """

    def __init__(self, degree: int) -> None:
        n = degree + 1
        nv = 2 * n
        # integral of |r''|^2 up to a constant factor: the squared second differences (the time scale only
        # scales the objective, so the Hessian is a constant)
        d2 = np.zeros((degree - 1, n))
        for i in range(degree - 1):
            d2[i, i:i + 3] = (1.0, -2.0, 1.0)
        hess = np.zeros((nv, nv))
        hess[:n, :n] = hess[n:, n:] = 2.0 * d2.T @ d2
        hess += 2.0 * _REG * np.eye(nv)
        na = 2 * (degree - 1)  # acceleration control points, both axes
        self.rows = 2 * degree + na + MAX_HALF_PLANES * n + SEPARATION_SAMPLES
        diff = np.zeros((2 * degree + na, nv))  # velocity (per degree / T) and acceleration (per d (d-1) / T^2) rows
        for axis in range(2):
            for i in range(degree):
                diff[axis * degree + i, axis * n + i:axis * n + i + 2] = (-1.0, 1.0)
            for i in range(degree - 1):
                diff[2 * degree + axis * (degree - 1) + i, axis * n + i:axis * n + i + 3] = (1.0, -2.0, 1.0)
        self.diff = diff
        # dense sparsities (the matrices are passed whole): nonzeros are the entries in column-major order
        self.solver = ca.conic("replan_qp", "daqp", {"h": ca.Sparsity.dense(nv, nv),
                                                     "a": ca.Sparsity.dense(self.rows, nv)}, {"error_on_fail": False})
        self.hess = hess
        self.fixed = [0, 1, n - 2, n - 1, n, n + 1, 2 * n - 2, 2 * n - 1]  # the end states' control points
        self.ramp = np.arange(n, dtype=float)
        self.index = np.arange(n)
        self._local = threading.local()

    def buffers(self) -> dict[str, np.ndarray]:
        """This thread's bound arrays: inputs ``h, g, a`` (a in column-major order), ``lba, uba, lbx, ubx``
        (and zero warm starts), output ``x``."""
        arrays = getattr(self._local, "arrays", None)
        if arrays is None:
            solver = self.solver
            buffer, evaluate = solver.buffer()
            arrays = {name: np.zeros(solver.nnz_in(i)) for i, name in enumerate(solver.name_in())}
            arrays["h"][:] = self.hess.ravel(order="F")
            for i, name in enumerate(solver.name_in()):
                # casadi's stub asks for the size in bytes as well: the binding takes it from the buffer
                buffer.set_arg(i, arrays[name].data)  # type: ignore[call-arg]
            out = {name: np.zeros(solver.nnz_out(i)) for i, name in enumerate(solver.name_out())}
            for i, name in enumerate(solver.name_out()):
                buffer.set_res(i, out[name].data)  # type: ignore[call-arg]  # as set_arg
            arrays["x"] = out["x"]
            arrays["A"] = arrays["a"].reshape(self.hess.shape[0], self.rows).T  # (rows, nv) view, column-major
            # the buffer holds raw pointers: every bound array (the unused outputs too) must outlive it
            self._local.arrays, self._local.out = arrays, out
            self._local.buffer, self._local.evaluate = buffer, evaluate
        return arrays

    def solve(self) -> bool:
        """Solve with the numbers in :meth:`buffers`; True if DAQP reports success and its answer ``x`` keeps
        what the QP asked (:meth:`answer_holds`)."""
        self._local.evaluate()
        return bool(self._local.buffer.stats()["success"]) and self.answer_holds()

    def answer_holds(self) -> bool:
        """True if ``x`` keeps the variables' bounds (the fixed end states among them) to ``FIXED_TOL_M`` and
        every row to ``ROW_TOL``.

        DAQP reports success on some infeasible QPs (a known DAQP defect, darnstrom/daqp#82): the answer then
        keeps the rows but moves the fixed control points, by up to 5 cm in the relay episodes, so the segment
        misses the contact it was for (``tests/planners/online/test_segment_feasibility.py`` has such a QP). On
        feasible QPs the fixed points hold to 1e-11 m and the rows to 1e-12: the tolerances separate the two by
        orders of magnitude (the moved answers moved them by 1e-6 m and more)."""
        arrays = self._local.arrays
        x = arrays["x"]
        if not ((x >= arrays["lbx"] - FIXED_TOL_M) & (x <= arrays["ubx"] + FIXED_TOL_M)).all():
            return False
        rows = arrays["A"] @ x
        return bool(((rows >= arrays["lba"] - ROW_TOL) & (rows <= arrays["uba"] + ROW_TOL)).all())


@lru_cache(maxsize=4)
def _qp(degree: int) -> _SegmentQP:
    return _SegmentQP(degree)


def bounded_segment(p0, v0, p1, v1, t0: float, t1: float, velocity_bound, degree: int = DEGREE,
                    limits: SegmentLimits | None = None, around: Segment | None = None,
                    acceleration_bound=None) -> Segment | None:
    """The convex QP: min integral |r''|^2 over degree-``degree`` Bezier control points, end states fixed,
    velocity (and acceleration) control points within the per-axis bounds, and the ``limits``. None if
    infeasible.

    ``around`` is the segment the separation rows are linearised about (default: the Hermite cubic).
    """
    qp = _qp(degree)
    buf = qp.buffers()
    diff = qp.diff
    n = degree + 1
    T = t1 - t0
    p0, v0, p1, v1 = (np.asarray(a, float) for a in (p0, v0, p1, v1))
    A, lba, uba, lbx, ubx = buf["A"], buf["lba"], buf["uba"], buf["lbx"], buf["ubx"]
    lba[:], uba[:] = -np.inf, np.inf
    k = degree / T
    na = 2 * (degree - 1)
    A[:2 * degree] = k * diff[:2 * degree]  # velocity control points (Eq. 25)
    A[2 * degree:2 * degree + na] = degree * (degree - 1) / T ** 2 * diff[2 * degree:]  # acceleration ones
    A[2 * degree + na:] = 0.0
    for axis in range(2):
        if velocity_bound is not None:
            lba[axis * degree:(axis + 1) * degree] = -float(velocity_bound[axis])
            uba[axis * degree:(axis + 1) * degree] = float(velocity_bound[axis])
        if acceleration_bound is not None:
            rows_a = slice(2 * degree + axis * (degree - 1), 2 * degree + (axis + 1) * (degree - 1))
            lba[rows_a], uba[rows_a] = -float(acceleration_bound[axis]), float(acceleration_bound[axis])
    if limits is not None and limits.box is not None:
        x0, x1, y0, y1 = limits.box
        # never ask the fixed ends to move: a robot touching the boundary starts on it
        lbx[:n], ubx[:n] = min(x0, p0[0], p1[0]), max(x1, p0[0], p1[0])
        lbx[n:], ubx[n:] = min(y0, p0[1], p1[1]), max(y1, p0[1], p1[1])
    else:
        lbx[:], ubx[:] = -np.inf, np.inf
    # end states: the first two and last two control points of each axis (Eq. 8 at s = 0 and 1)
    fixed = qp.fixed
    values = [p0[0], p0[0] + v0[0] / k, p1[0] - v1[0] / k, p1[0], p0[1], p0[1] + v0[1] / k, p1[1] - v1[1] / k, p1[1]]
    lbx[fixed] = ubx[fixed] = values
    if limits is not None:
        r = 2 * degree + na
        idx = qp.index
        for normal, offset in limits.half_planes[:MAX_HALF_PLANES]:
            normal = np.asarray(normal, float)
            lo = min(offset, normal @ p0, normal @ p1)  # never ask the fixed ends to move
            A[r + idx, idx] = normal[0]
            A[r + idx, n + idx] = normal[1]
            lba[r:r + n] = lo
            r += n
        r = 2 * degree + na + MAX_HALF_PLANES * n
        base = around if around is not None else hermite(p0, v0, p1, v1, t0, t1)
        for s, normal, offset in separation_rows(base, limits)[:SEPARATION_SAMPLES]:
            w = bezier.bernstein(degree, s)[0]
            A[r, :n], A[r, n:] = normal[0] * w, normal[1] * w
            lba[r] = offset
            r += 1
    g = buf["g"]  # a pull toward the straight line (the Tikhonov term)
    g[:n], g[n:] = _linspace(p0[0], p1[0], qp.ramp), _linspace(p0[1], p1[1], qp.ramp)
    g *= -2.0 * _REG
    if not qp.solve():  # infeasible, or an answer that breaks what was asked (see _SegmentQP.answer_holds)
        return None
    x = buf["x"]
    return Segment(t0, t1, x.reshape(2, n).T.copy())  # [x_0..x_d, y_0..y_d] as (d + 1, 2) points


def _linspace(start: float, stop: float, ramp: np.ndarray) -> np.ndarray:
    """``np.linspace(start, stop, len(ramp))`` with ``ramp = arange(len)``, computed the same way (the same
    numbers to the last bit) without its argument handling, which was a tenth of a QP call."""
    div = len(ramp) - 1
    delta = stop - start
    step = delta / div
    y = ramp / div * delta if step == 0 else ramp * step
    y += start
    y[-1] = stop
    return y


__all__ = ["DEGREE", "MAX_HALF_PLANES", "SEPARATION_SAMPLES", "SegmentLimits", "WayRound", "bounded_segment",
           "hermite", "separation_rows"]
