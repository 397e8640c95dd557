"""The ``kinematic`` fidelity's substep loop: the thesis's Eq. (5), the cargo without inertia.

What the thesis plans with. The cargo has no inertia: every substep its velocity is set so
that it moves exactly as Eq. (5), ``x' = w * sum_i (a_i - x) / |a_i - x|`` over the reeling anchors ``a_i``,
integrated by one classical Runge-Kutta (RK4) step; with no reeling tether it stops. One tether: a straight
line toward the anchor at speed ``w``. Two: the branch of the hyperbola ``|x - a_1| - |x - a_2| = const``
(both distances shrink at the same rate ``w (1 + cos theta)``) at speed ``2 w cos(theta / 2)``, ``theta`` the
angle between the tethers at the cargo. Where the cargo touches a wall, the velocity component into it is
dropped (it slides, frictionless); a held tether drops the component away from its anchor.

Eq. (5)'s winch work: every reeling winch at its limit times the rate its tether shrinks. Three paths,
bit-identical: the substeps in C where that is built (:mod:`impact_env.tether.native`,
:meth:`_step_kinematic_native`), written out with chipmunk's C functions (:meth:`_step_kinematic_fast`), and
through pymunk's public API (:meth:`_substep_kinematic`).
"""

from __future__ import annotations

import math

from impact_env.tether.checks import TetherChecks
from impact_env.tether.eq5 import rk4_eq5, rk4_one, rk4_two
from impact_env.tether.stepping import Tether
from impact_env.tether.stepping import chipmunk_lib as _cp


class KinematicLoop(TetherChecks):
    """The kinematic substeps of :class:`~impact_env.tether.physics.TetherWorld`."""

    def _step_kinematic_native(self) -> None:
        """:meth:`_step_kinematic_fast` with its substeps in C (:mod:`impact_env.tether.native`). The loop runs
        while nothing but arithmetic is needed; the substeps that need the wall test (or meet a cargo at an
        anchor) run here in Python, as do the tether checks and attachments once due, with the same state."""
        loop, dt, hypot = self._kinematic_loop, self.dt_s, math.hypot
        assert loop is not None  # the caller runs this only with the compiled loop
        end = self.n_substeps_done + self.substeps
        while self.n_substeps_done < end:
            active = self._active
            if active is None:
                active = self._active = [t for t in self._tethers if t is not None and t.pulling]
                self._budget = -1.0
            if self._planned is not active:  # every change of the tethers makes a new active list
                reeling = [t for t in active if not t.held]
                w = reeling[0].w if reeling else 0.0
                same = all(t.w == w for t in reeling)
                loop.set_plan([(t.ax, t.ay) for t in reeling], w, None if same else [t.w for t in reeling],
                              [(t.ax, t.ay, t.length) for t in active if t.held], bool(active))
                self._planned = active
            (cx, cy), (sx, sy) = self._checked_at, self._wall_seen_at
            n, self.winch_work_J, stop = loop.run(end - self.n_substeps_done, self.n_substeps_done,
                                                  self.winch_work_J, cx, cy, self._budget, sx, sy,
                                                  self._wall_margin if self._cache else -math.inf,
                                                  self._next_ready)
            self.n_substeps_done = n
            if stop == 1:  # a substep that needs the wall test: Python takes it (and its checks)
                self._step_kinematic_fast(1)
            elif stop == 2:  # the tether checks or attachments are due after the substep just taken
                p = _cp.cpBodyGetPosition(self._body_ptr)
                x, y = p.x, p.y
                if active:
                    cx, cy = self._checked_at
                    if not hypot(x - cx, y - cy) < self._budget:
                        self._check_tethers(active)
                if self._next_ready <= n * dt + 1e-9:
                    self._activate_ready()

    def _step_kinematic_fast(self, substeps: int | None = None) -> None:
        cp, body, space, dt, hypot = _cp, self._body_ptr, self._space_ptr, self.dt_s, math.hypot
        get_pos, set_vel, step = cp.cpBodyGetPosition, cp.cpBodySetVelocity, cp.cpSpaceStep
        winch, cache = self._winch_N, self._cache
        x, y, _, _ = self._begin_fast()
        total = self.winch_work_J
        n = self.n_substeps_done
        plan = None  # what the pulling tethers make of Eq. (5), rebuilt when they change
        for _ in range(self.substeps if substeps is None else substeps):
            active = self._active
            if active is None or plan is None or plan[0] is not active:
                if active is None:
                    active = self._active = [t for t in self._tethers if t is not None and t.pulling]
                    self._budget = -1.0
                reeling = [t for t in active if not t.held]
                held = [t for t in active if t.held]
                w = reeling[0].w if reeling else 0.0
                same = all(t.w == w for t in reeling)
                plan = (active, reeling, held, w, None if same else [t.w for t in reeling],
                        [(t.ax, t.ay) for t in reeling])
            _, reeling, held, w, ws, points = plan
            if reeling:
                if len(points) == 1 and ws is None:
                    nx, ny = rk4_one(x, y, points[0][0], points[0][1], w, dt)
                elif len(points) == 2 and ws is None:
                    nx, ny = rk4_two(x, y, points[0][0], points[0][1], points[1][0], points[1][1], w, dt)
                else:
                    nx, ny = rk4_eq5(x, y, points, w, dt, ws)
                vx, vy = (nx - x) / dt, (ny - y) / dt
                if held:
                    vx, vy = keep_lengths(x, y, vx, vy, held, dt)
                sx, sy = self._wall_seen_at
                if not (cache and hypot(x - sx, y - sy) < self._wall_margin):
                    vx, vy = self._slide_along_walls(x, y, vx, vy)
                work = 0.0
                for ax, ay in points:
                    ux, uy = ax - x, ay - y
                    rate = (vx * ux + vy * uy) / hypot(ux, uy)
                    if rate > 0.0:
                        work += winch * rate * dt
                total += work
            else:
                vx = vy = 0.0
            set_vel(body, (vx, vy))
            step(space, dt)
            n += 1
            p = get_pos(body)
            x, y = p.x, p.y
            if active:
                cx, cy = self._checked_at
                if not hypot(x - cx, y - cy) < self._budget:
                    self.n_substeps_done, self.winch_work_J = n, total
                    self._check_tethers(active)
                    if self._active is None:
                        plan = None
            if self._next_ready <= n * dt + 1e-9:
                self.n_substeps_done, self.winch_work_J = n, total
                self._activate_ready()
                if self._active is None:
                    plan = None
        self.n_substeps_done, self.winch_work_J = n, total

    def _substep_kinematic(self, active: list[Tether], x: float, y: float, vx0: float, vy0: float) -> None:
        dt = self.dt_s
        reeling = [t for t in active if not t.held]
        if reeling:
            anchors = [(t.ax, t.ay) for t in reeling]
            w = reeling[0].w
            ws = None if all(t.w == w for t in reeling) else [t.w for t in reeling]
            nx, ny = rk4_eq5(x, y, anchors, w, dt, ws)
            vx, vy = (nx - x) / dt, (ny - y) / dt
            if len(reeling) < len(active):
                vx, vy = keep_lengths(x, y, vx, vy, [t for t in active if t.held], dt)
            vx, vy = self._slide_along_walls(x, y, vx, vy)
            # Eq. (5)'s tension: every reeling winch at its limit, times the rate its tether shrinks
            work = 0.0
            for t in reeling:
                ux, uy = t.ax - x, t.ay - y
                rate = (vx * ux + vy * uy) / math.hypot(ux, uy)
                if rate > 0.0:
                    work += self._winch_N * rate * dt
            self.winch_work_J += work
        else:
            vx = vy = 0.0
        if self._fast:
            _cp.cpBodySetVelocity(self._body_ptr, (vx, vy))
        else:
            self.cargo.velocity = (vx, vy)
        self._space_step(dt)


def keep_lengths(x: float, y: float, vx: float, vy: float, held: list[Tether], dt: float) -> tuple[float, float]:
    """The velocity over the next ``dt`` that lengthens no held tether: the component away from each held anchor
    dropped, then the step shortened radially where it would still end farther than the tether's held length
    (moving across a tether lengthens it to second order); two passes settle two of them."""
    for _ in range(2):
        for t in held:
            ux, uy = t.ax - x, t.ay - y
            d = math.hypot(ux, uy)
            ux, uy = ux / d, uy / d
            toward = vx * ux + vy * uy
            if toward < 0.0:
                vx, vy = vx - toward * ux, vy - toward * uy
    for _ in range(2):
        for t in held:
            px, py = x + vx * dt - t.ax, y + vy * dt - t.ay
            d = math.hypot(px, py)
            if d > t.length > 0.0:
                s = t.length / d
                vx, vy = (t.ax + px * s - x) / dt, (t.ay + py * s - y) / dt
    return vx, vy

