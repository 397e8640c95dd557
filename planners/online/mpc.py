"""Impact-aware nonlinear MPC of one planar freeflyer (paper Sec. VII, Eq. 30-31).

Model (Eq. 30): state ``x = [px, py, theta, vx, vy, omega]`` (m, rad, m/s, rad/s), input ``u = [Fx, Fy, tau]``
in the BODY frame (N, N m), one RK4 step of ``dt_s`` per control period with the input held
(:func:`rk4_step` is the same step in numpy). The problem (Eq. 31) tracks a reference over N nodes with
bounded inputs; a planned impact (:class:`ImpactSpec`) fixes the pre-impact state at its node through exact
L1 penalties and continues the prediction from the post-impact velocity; keep-offs (:class:`AvoidSpec`,
:class:`HalfPlaneSpec`) are half-planes with slacks, re-linearised every solve.

The solvers (``MPCConfig.solver``: ``"sqp"``, ``"fatrop"``, ``"ipopt"``) are built ONCE, every per-step
quantity a parameter, and warm-started from the previous solution; a failed solve is retried by
``fallback_solver`` and never returns NaN. Never CasADi's ``highs`` plugin (its libhighs clashes with highspy
in one process). The formulation in full, and why keep-offs are half-planes: ``docs/expert_design.md#mpc``.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace
from typing import Any

import casadi as ca
import numpy as np

from impact_env.transport.scenario import Body
from planners.online.freeflyer import _rk4_sx, rk4_step, state_from_sim
from planners.online.mpc_specs import (
    _NSI,
    _WEIGHTS,
    NU,
    NX,
    SOLVERS,
    AvoidSpec,
    HalfPlaneSpec,
    ImpactSpec,
    MPCConfig,
    MPCInputError,
    MPCResult,
    _vector,
)

__all__ = ["SOLVERS", "AvoidSpec", "FreeflyerMPC", "HalfPlaneSpec", "ImpactSpec", "MPCConfig", "MPCInputError",
           "MPCResult", "rk4_step", "state_from_sim"]


class FreeflyerMPC:
    """Nonlinear MPC of one freeflyer robot; build once, then call :meth:`solve` every control period.

    Args:
        robot: the robot's :class:`~impact_env.transport.scenario.Body` (mass, inertia, thrust and torque limits).
        config: horizon, dt, weights, solver; default :class:`MPCConfig`.
        heading_ref: heading (rad) the robot is held at, e.g. its initial heading; measured headings that
            wrapped around (theta + 2 pi k) are tracked to the nearest equivalent of it.

    Attributes:
        failures: solves that returned ``success=False``; ``fallbacks``: solves rescued by the fallback
        solver; ``solves``: all solves.
    """

    def __init__(self, robot: Body, config: MPCConfig | None = None, heading_ref: float = 0.0) -> None:
        if not robot.is_robot:
            raise MPCInputError(f"body {robot.name!r} has no thrust limits: it is not a robot")
        if not math.isfinite(heading_ref):
            raise MPCInputError(f"heading_ref must be finite, got {heading_ref!r}")
        self.robot = robot
        self.config = cfg = config if config is not None else MPCConfig()
        self.heading_ref = float(heading_ref)
        self.horizon = cfg.horizon
        self.limits = np.array(robot.wrench_limits, dtype=float)
        self.bounds = cfg.thrust_fraction * self.limits
        self.failures = self.fallbacks = self.solves = 0
        self._build(robot, cfg)
        self._p = np.zeros(self._np)
        self._write_weights()
        self._solvers = {cfg.solver: self._make_solver(cfg.solver)}
        if cfg.fallback_solver is not None and cfg.fallback_solver != cfg.solver:
            self._solvers[cfg.fallback_solver] = self._make_solver(cfg.fallback_solver)
        self._guess: np.ndarray | None = None
        # the solvers' inputs: numpy arrays bound once to every solver's zero-copy call buffer (_SolverCall)
        self._in = {"x0": np.zeros(self._nw), "p": self._p, "lbx": self._lbx, "ubx": self._ubx,
                    "lbg": self._lbg.copy(), "ubg": self._ubg.copy(), "lam_x0": np.zeros(self._nw),
                    "lam_g0": np.zeros(self._ng)}
        self._lam_x = self._in["lam_x0"]
        self._lam_g = self._in["lam_g0"]
        self._calls: dict[str, _SolverCall] = {}
        self._off_normals = np.zeros((self.horizon + 1, self._nka, 2))
        self._off_normals[:, :, 0] = 1.0
        self._cold_multipliers()

    # ------------------------------------------------------------------------------------- building
    def _build(self, robot: Body, cfg: MPCConfig) -> None:
        n = cfg.horizon
        nk = self._nka = cfg.keep_off_rows
        sizes = {"x0": NX, "ref": 4 * (n + 1), "heading": 1, "select": n + 1, "v_after": 2,
                 "normals": 2 * nk * (n + 1), "weights": len(_WEIGHTS)}
        self._pslice, start = {}, 0
        for name, size in sizes.items():
            self._pslice[name] = slice(start, start + size)
            start += size
        self._np = start
        P = ca.SX.sym("p", start)
        par = {name: P[s] for name, s in self._pslice.items()}
        ref = ca.reshape(par["ref"], 4, n + 1)  # column k = [x, y, vx, vy] at node k
        normals = ca.reshape(par["normals"], 2, nk * (n + 1))  # column k * nk + j: row j of node k
        sel = par["select"]
        q_pos, q_vel, q_head, q_omega, r_in, term = (par["weights"][i] for i in range(len(_WEIGHTS)))
        scale = 1.0 / self.limits

        w, lbw, ubw, g, lbg, ubg = [], [], [], [], [], []
        self._vblocks: dict[tuple[str, int], slice] = {}
        self._gblocks: dict[tuple[str, int], slice] = {}
        counts = {"w": 0, "g": 0}

        def add_var(name: str, k: int, size: int, lo: list[float], hi: list[float]) -> ca.SX:
            v = ca.SX.sym(f"{name}{k}", size)
            self._vblocks[(name, k)] = slice(counts["w"], counts["w"] + size)
            counts["w"] += size
            w.append(v)
            lbw.extend(lo)
            ubw.extend(hi)
            return v

        def add_con(name: str, k: int, expr: ca.SX, lo: list[float], hi: list[float]) -> None:
            self._gblocks[(name, k)] = slice(counts["g"], counts["g"] + expr.shape[0])
            counts["g"] += expr.shape[0]
            g.append(expr)
            lbg.extend(lo)
            ubg.extend(hi)

        inf = math.inf
        # every entry is set in the first loop below (x_0 is the parameter; no slacks at stage 0)
        xs: list[ca.SX] = [par["x0"]] * (n + 1)
        us: list[ca.SX] = [ca.SX()] * n
        slacks: list[ca.SX] = [ca.SX()] * (n + 1)
        cost: ca.SX | int = 0
        for k in range(n + 1):  # stage k: [x_k], [u_k], [slacks_k]
            if k > 0:
                xs[k] = add_var("x", k, NX, [-inf] * NX, [inf] * NX)
            if k < n:
                us[k] = add_var("u", k, NU, list(-self.bounds), list(self.bounds))
            if k > 0:
                slacks[k] = add_var("s", k, _NSI + nk, [0.0] * (_NSI + nk), [inf] * (_NSI + nk))
        for k in range(n + 1):  # constraints of stage k: dynamics k -> k+1, then the path constraints of node k
            x = xs[k]
            if k < n:
                # Impact at node k: the step to k+1 starts from the planned post-impact velocity.
                v_start = (1 - sel[k]) * x[3:5] + sel[k] * par["v_after"]
                x_start = ca.vertcat(x[0:3], v_start, x[5])
                add_con("dyn", k, xs[k + 1] - _rk4_sx(x_start, us[k], robot, cfg.dt_s), [0.0] * NX, [0.0] * NX)
                cost += r_in * ca.sumsqr(us[k] * scale)
            if k > 0:
                # Path rows are switched on and off through their bounds in solve() (+-inf when off): rows
                # multiplied by a 0/1 parameter would leave duplicate "sigma >= 0" rows that stall qrqp.
                s_imp, s_av = slacks[k][0:_NSI], slacks[k][_NSI:]
                z = ca.vertcat(x[0:2], x[3:5])
                # keep-off rows n_j . p + sigma_j >= offset_j (the offsets are the rows' bounds, in solve())
                gaps = [ca.dot(normals[:, k * nk + j], x[0:2]) + s_av[j] for j in range(nk)]
                add_con("path", k, ca.vertcat(z - s_imp[0:4] + s_imp[4:8], *gaps), [-inf] * (4 + nk),
                        [inf] * (4 + nk))
                wk = term if k == n else 1.0
                node = (q_pos * ca.sumsqr(x[0:2] - ref[0:2, k]) + q_vel * ca.sumsqr(x[3:5] - ref[2:4, k])
                        + q_head * (x[2] - par["heading"]) ** 2 + q_omega * x[5] ** 2)
                cost += wk * node
                # the small quadratic terms keep the slack block of the Hessian positive definite
                cost += cfg.impact_penalty * (ca.sum1(s_imp) + 1e-3 * ca.sumsqr(s_imp))
                cost += cfg.avoid_penalty * (ca.sum1(s_av) + ca.sumsqr(s_av))
        self._nlp: dict[str, ca.SX] = {"x": ca.vertcat(*w), "p": P, "f": ca.SX(cost), "g": ca.vertcat(*g)}
        self._nw, self._ng = counts["w"], counts["g"]
        self._lbx, self._ubx = np.array(lbw), np.array(ubw)
        self._lbg, self._ubg = np.array(lbg), np.array(ubg)
        self._stage_sizes = (
            [0] + [NX] * n,  # nx: x_0 is a parameter, not a variable
            [NU] + [NU + _NSI + nk] * (n - 1) + [_NSI + nk],  # nu
            [0] + [4 + nk] * n,  # ng: path constraints per stage (impact 4, keep-off nk)
        )
        # index maps: shifting the warm start by one stage, reading states and inputs
        self._shift_w = self._shift_map(self._vblocks, self._nw)
        self._shift_g = self._shift_map(self._gblocks, self._ng)
        self._x_idx = np.array([np.arange(self._nw)[self._vblocks[("x", k)]] for k in range(1, n + 1)])
        self._xy_idx = self._x_idx[:, 0:2].copy()
        self._avoid_rows = np.array([[self._gblocks[("path", k)].start + 4 + j for j in range(nk)]
                                     for k in range(1, n + 1)])  # (N, nk)
        self._slack_idx = np.concatenate([np.arange(self._nw)[self._vblocks[("s", k)]] for k in range(1, n + 1)])
        self._slack_lam = -np.tile([cfg.impact_penalty] * _NSI + [cfg.avoid_penalty] * nk, n)
        self._u_idx = np.array([np.arange(self._nw)[self._vblocks[("u", k)]] for k in range(n)])

    @staticmethod
    def _shift_map(blocks: dict[tuple[str, int], slice], size: int) -> np.ndarray:
        """Index array: block (name, k) takes the values of (name, k+1), the last block keeps its own."""
        idx = np.arange(size)
        for (name, k), s in blocks.items():
            src = blocks.get((name, k + 1), s)
            idx[s] = np.arange(size)[src]
        return idx

    def _make_solver(self, name: str) -> ca.Function:
        cfg = self.config
        # the multipliers of the parameters are never read: not computing them saves an extra derivative
        # evaluation after every solve (a tenth of an sqpmethod solve here); x, lam_x, lam_g are unchanged
        common = {"calc_lam_p": False}
        if name == "sqp":
            # Gauss-Newton Hessian (the cost's, constant and positive definite) and full steps, as in
            # real-time MPC. The exact Hessian is indefinite in (theta, F) once large multipliers (impact
            # node, keep-off) flow into the dynamics; eigen-clipped it made sqpmethod cycle (9 failures in
            # 12 000 closed-loop solves of benchmarks/mpc.py). With the line search on, Gauss-Newton steps
            # were rejected for up to 36 iterations while sliding along a keep-off disc (N = 20); full steps
            # converge in <= 13 there, with no failure. tol_du is in cost units per variable unit (costs
            # are 1e0-1e3).
            nlp = self._nlp
            lam_f, lam_g = ca.SX.sym("lam_f"), ca.SX.sym("lam_g", nlp["g"].shape[0])
            hess = ca.triu(lam_f * ca.hessian(nlp["f"], nlp["x"])[0])
            opts: dict[str, Any]  # casadi's options: numbers, strings, functions and nested dicts
            opts = {"qpsol": "qrqp", "max_iter": cfg.sqp_max_iter, "tol_pr": 1e-6, "tol_du": 1e-4, "max_iter_ls": 0,
                    "hess_lag": ca.Function("nlp_hess_l", [nlp["x"], nlp["p"], lam_f, lam_g], [hess],
                                            ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"]),
                    "qpsol_options": {"print_iter": False, "print_header": False, "print_info": False,
                                      "error_on_fail": False},
                    "print_header": False, "print_iteration": False, "print_status": False, "print_time": False,
                    **common}
            return ca.nlpsol("mpc_sqp", "sqpmethod", self._nlp, opts)
        if name == "fatrop":
            nx, nu, ng = self._stage_sizes
            opts = {"structure_detection": "manual", "N": self.horizon, "nx": nx, "nu": nu, "ng": ng,
                    "expand": True, "print_time": False,
                    "fatrop": {"print_level": 0, "max_iter": 100, "tol": 1e-6}, **common}
            return ca.nlpsol("mpc_fatrop", "fatrop", self._nlp, opts)
        opts = {"print_time": False, **common,
                "ipopt": {"print_level": 0, "sb": "yes", "tol": 1e-6, "max_iter": 100,
                          "warm_start_init_point": "yes", "warm_start_bound_push": 1e-6,
                          "warm_start_mult_bound_push": 1e-6, "mu_init": 1e-3}}
        return ca.nlpsol("mpc_ipopt", "ipopt", self._nlp, opts)

    def _bind(self, name: str) -> _SolverCall:
        self._calls[name] = call = _SolverCall(self._solvers[name], self._in)
        return call

    # ------------------------------------------------------------------------------------- interface
    def reset(self) -> None:
        """Forget the warm start (call at the start of an episode or after a large state jump)."""
        self._guess = None
        self._cold_multipliers()

    def _cold_multipliers(self) -> None:
        """Zero multipliers, except the slack bounds: active, with their exact multipliers (minus the penalty
        gradient). qrqp takes its initial active set from them, and sqpmethod's first dual residual is 0."""
        self._lam_x[:] = 0.0
        self._lam_g[:] = 0.0
        self._lam_x[self._slack_idx] = self._slack_lam

    def update_weights(self, **weights: float) -> None:
        """Change cost weights (names of :class:`MPCConfig` weight fields) without rebuilding the solver."""
        unknown = sorted(set(weights) - set(_WEIGHTS))
        if unknown:
            raise MPCInputError(f"unknown weight(s) {unknown}; weights are {', '.join(_WEIGHTS)}")
        changes: dict[str, Any] = dict(weights)
        self.config = replace(self.config, **changes)  # MPCConfig checks the values
        self._write_weights()

    def _write_weights(self) -> None:
        self._p[self._pslice["weights"]] = [getattr(self.config, name) for name in _WEIGHTS]

    def solve(self, state: np.ndarray, reference: np.ndarray, impact: ImpactSpec | None = None,
              avoid: AvoidSpec | HalfPlaneSpec | list | None = None) -> MPCResult:
        """Solve the MPC problem from the measured ``state`` (6,) tracking ``reference`` (N+1, 4).

        ``reference[k] = [x, y, vx, vy]`` (m, m/s) at time t + k * dt_s (row 0 is not penalised).
        Raises MPCInputError (a ValueError) on wrong shapes, NaN/inf values or an impact step outside 0..N.
        """
        start = time.perf_counter()
        n = self.horizon
        x0 = _vector(state, (NX,), "state")
        ref = _vector(reference, (n + 1, 4), "reference")
        p, ps = self._p, self._pslice
        p[ps["x0"]] = x0
        p[ps["ref"]] = ref.ravel()
        two_pi = 2.0 * math.pi
        p[ps["heading"]] = self.heading_ref + two_pi * round((float(x0[2]) - self.heading_ref) / two_pi)
        p[ps["select"]] = 0.0
        p[ps["v_after"]] = 0.0
        lbg, ubg = self._in["lbg"], self._in["ubg"]
        lbg[:], ubg[:] = self._lbg, self._ubg  # all path rows off (+-inf)
        if impact is not None:
            if not isinstance(impact, ImpactSpec):
                raise MPCInputError(f"impact must be an ImpactSpec or None, got {type(impact).__name__}")
            if not 0 <= impact.step <= n:
                raise MPCInputError(f"ImpactSpec.step must be in 0..{n} (horizon nodes), got {impact.step}")
            p[ps["select"].start + impact.step] = 1.0
            p[ps["v_after"]] = impact.velocity_after
            if impact.step > 0:  # node 0 is measured: only the velocity jump applies there
                row = self._gblocks[("path", impact.step)].start
                lbg[row:row + 4] = ubg[row:row + 4] = np.r_[impact.position, impact.velocity_before]
        specs = self._avoid_specs(avoid)
        guess = self._initial_guess(x0, ref) if self._guess is None else self._guess
        normals = self._off_normals.copy()  # rows that are off still need a finite normal: +x
        for j, spec in enumerate(specs):
            if isinstance(spec, AvoidSpec):
                normals[:, j] = self._normals(guess, x0, ref, spec.centers)
                offsets = np.einsum("kd,kd->k", normals[:, j], spec.centers) + spec.min_distance
            else:
                normals[:, j], offsets = spec.normals, spec.offsets
            active = spec.active[1:]
            lbg[self._avoid_rows[active, j]] = offsets[1:][active]  # n . p + sigma >= offset
        p[ps["normals"]] = normals.ravel()
        self._in["x0"][:] = guess
        for name in self._solvers:  # the primary first, then the fallback
            call = self._calls.get(name) or self._bind(name)
            stats = call()
            w = call.out["x"].copy()
            ok = bool(stats["success"]) and bool(np.isfinite(w).all())
            if ok:
                break
        self.solves += 1
        if ok:
            self.fallbacks += name != self.config.solver
            self._lam_x[:] = call.out["lam_x"][self._shift_w]
            self._lam_g[:] = call.out["lam_g"][self._shift_g]
        else:
            self.failures += 1
            if not np.all(np.isfinite(w)):
                w = guess  # a NaN iterate is useless: keep the previous plan
            self._cold_multipliers()
        self._guess = w[self._shift_w]
        inputs = np.minimum(np.maximum(w[self._u_idx], -self.bounds), self.bounds)
        predicted = np.empty((n + 1, NX))
        predicted[0], predicted[1:] = x0, w[self._x_idx]
        result = MPCResult(
            wrench=inputs[0].copy(), success=ok, solve_ms=0.0, predicted=predicted, inputs=inputs,
            status=str(stats.get("return_status", "")), iterations=int(stats.get("iter_count", 0)), solver=name,
        )
        if impact is not None and impact.step > 0:
            node = predicted[impact.step]
            result.impact_error = float(np.max(np.abs(np.r_[node[0:2] - impact.position,
                                                            node[3:5] - impact.velocity_before])))
        positions = predicted[:, 0:2]
        clearances = [spec.clearance(positions) for spec in specs if spec.active[1:].any()]
        if clearances:
            result.min_clearance_m = float(min(clearances))
        result.solve_ms = (time.perf_counter() - start) * 1e3
        return result

    def _avoid_specs(self, avoid) -> list:
        """The keep-off specs of a solve() call as a checked list (None, one spec, or a list of specs)."""
        if avoid is None:
            return []
        specs = list(avoid) if isinstance(avoid, (list, tuple)) else [avoid]
        if len(specs) > self._nka:
            raise MPCInputError(f"{len(specs)} keep-off specs given but MPCConfig.keep_off_rows = {self._nka}")
        n = self.horizon
        for spec in specs:
            if not isinstance(spec, (AvoidSpec, HalfPlaneSpec)):
                raise MPCInputError(f"avoid must be an AvoidSpec, a HalfPlaneSpec, a list of them or None, "
                                    f"got {type(spec).__name__}")
            spec.check(n)
        return specs

    def _normals(self, guess: np.ndarray, x0: np.ndarray, ref: np.ndarray, centers: np.ndarray) -> np.ndarray:
        """Unit normals (N+1, 2) of the keep-off half-planes: from each centre towards the planned position
        (previous solution shifted), else the current position, else the reference, else +x."""
        planned = np.empty((self.horizon + 1, 2))
        planned[0], planned[1:] = x0[0:2], guess[self._xy_idx]
        v = planned - centers
        norm = np.hypot(v[:, 0], v[:, 1])
        if (norm > 1e-9).all():  # the usual case: every node has a planned position off the centre
            return v / norm[:, None]
        out = np.tile([1.0, 0.0], (self.horizon + 1, 1))
        todo = np.ones(self.horizon + 1, dtype=bool)
        for points in (planned, np.broadcast_to(x0[0:2], planned.shape), ref[:, 0:2]):
            v = points - centers
            norm = np.hypot(v[:, 0], v[:, 1])
            use = todo & (norm > 1e-9)
            out[use] = v[use] / norm[use, None]
            todo &= ~use
        return out

    def _initial_guess(self, x0: np.ndarray, ref: np.ndarray) -> np.ndarray:
        """Cold start: states on the reference, heading and yaw rate as measured, zero inputs and slacks."""
        w = np.zeros(self._nw)
        for k in range(1, self.horizon + 1):
            w[self._vblocks[("x", k)]] = [ref[k, 0], ref[k, 1], x0[2], ref[k, 2], ref[k, 3], 0.0]
        return w


class _SolverCall:
    """A CasADi solver called through its zero-copy buffer (``Function.buffer``).

    ``solver(x0=..., p=...)`` with numpy arguments converts each array to a CasADi matrix and each result
    back, at a fixed cost per array (about 25 us) plus one per number: with the eight inputs and three
    outputs of this MPC that was about a third of a solve. The buffer reads the inputs from, and writes the
    results into, numpy arrays bound once (``inputs``: name -> array, shared by every solver of the MPC and
    updated in place by :meth:`FreeflyerMPC.solve`); the numbers the solver sees are the same.
    """

    def __init__(self, solver: ca.Function, inputs: dict[str, np.ndarray]) -> None:
        self.solver = solver
        self.buffer, self._eval = solver.buffer()
        for i, name in enumerate(solver.name_in()):
            arr = inputs[name]
            if arr.dtype != np.float64 or not arr.flags.c_contiguous or arr.size != solver.nnz_in(i):
                raise MPCInputError(f"solver input {name!r} must be a contiguous float array of "
                                    f"{solver.nnz_in(i)} numbers")
            # casadi's stub asks for the size in bytes as well: the binding takes it from the buffer
            self.buffer.set_arg(i, arr.data)  # type: ignore[call-arg]
        self.out = {name: np.zeros(solver.nnz_out(i)) for i, name in enumerate(solver.name_out())}
        for i, name in enumerate(solver.name_out()):
            self.buffer.set_res(i, self.out[name].data)  # type: ignore[call-arg]  # as set_arg

    def __call__(self) -> dict:
        """Solve with the bound inputs; the results are in ``out``; returns the solver's stats."""
        self._eval()
        return self.buffer.stats()
