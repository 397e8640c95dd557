"""The ``reel`` fidelity's substep loop: each tether a pymunk slide joint reeled in at ``w``.

Each tether is a pymunk slide joint whose maximum length is set, every substep, to the current
distance minus ``w dt``, with the joint's ``max_force`` at the winch limit and its error fully corrected in
one step. So a winch reels in at least at ``w`` whenever its force suffices, can only pull (a slack tether
exerts nothing), and the cargo keeps its momentum: a released cargo drifts on, and a new tether keeps the
velocity component across it. Several tethers: the cargo must approach each anchor at ``w`` or faster, so when
both of two tethers are taut the cargo moves along the bisector at ``w / cos(theta / 2)`` (each distance
shrinks at exactly ``w``), not at Eq. (5)'s ``2 w cos(theta / 2)``: equal at ``theta = 90 deg``, half of it
for parallel tethers, and growing without bound toward opposite tethers, where the winch limit takes over.
A held tether keeps its length: it stops, within the winch limit, a cargo moving away from its anchor,
and does not pull it back (a locked drum, not a spring: the joint corrects no length error).

pymunk moves the bodies first and solves the joints at the moved positions, so the length error it sees is ``w
dt`` exactly when the limit is taken from the predicted position. The winch work is each joint's impulse times
the substep's mean speed toward its anchor, the positive parts summed. Two paths, bit-identical: written out
with chipmunk's C functions (:meth:`_step_reel_fast`, two pulling tethers spelled out) and through pymunk's
public API (:meth:`_substep_reel`).
"""

from __future__ import annotations

import math

from impact_env.tether.checks import TetherChecks
from impact_env.tether.stepping import Tether
from impact_env.tether.stepping import chipmunk_lib as _cp


class ReelLoop(TetherChecks):
    """The reel substeps of :class:`~impact_env.tether.physics.TetherWorld`."""

    def _step_reel_fast(self) -> None:
        cp, body, space, dt, hypot = _cp, self._body_ptr, self._space_ptr, self.dt_s, math.hypot
        get_pos, get_vel, set_max, step, impulse = (cp.cpBodyGetPosition, cp.cpBodyGetVelocity, cp.cpSlideJointSetMax,
                                                    cp.cpSpaceStep, cp.cpConstraintGetImpulse)
        x, y, vx0, vy0 = self._begin_fast()
        total = self.winch_work_J  # the same additions in the same order as _substep's, kept in a local
        n = self.n_substeps_done
        pair = None  # the two pulling tethers' constants, the common case written out below
        for _ in range(self.substeps):
            active = self._active
            if active is None:
                active = self._active = [t for t in self._tethers if t is not None and t.pulling]
                self._budget = -1.0
            px, py = x + vx0 * dt, y + vy0 * dt
            if len(active) == 2:
                if pair is None or pair[0] is not active:
                    t1, t2 = active
                    pair = (active, t1.ax, t1.ay, t1.jptr, None if t1.held else t1.w * dt,
                            t2.ax, t2.ay, t2.jptr, None if t2.held else t2.w * dt)
                _, a1x, a1y, j1, s1, a2x, a2y, j2, s2 = pair
                d = hypot(a1x - px, a1y - py)
                u1x, u1y = (a1x - px) / d, (a1y - py) / d
                if s1 is not None:
                    set_max(j1, max(0.0, d - s1))
                d = hypot(a2x - px, a2y - py)
                u2x, u2y = (a2x - px) / d, (a2y - py) / d
                if s2 is not None:
                    set_max(j2, max(0.0, d - s2))
                step(space, dt)
                v = get_vel(body)
                vx1, vy1 = v.x, v.y
                p = get_pos(body)
                x, y = p.x, p.y
                n += 1
                mx, my = 0.5 * (vx0 + vx1), 0.5 * (vy0 + vy1)
                work = impulse(j1) * (u1x * mx + u1y * my)
                if work > 0.0:
                    total += work
                work = impulse(j2) * (u2x * mx + u2y * my)
                if work > 0.0:
                    total += work
            else:
                units = []
                for t in active:
                    ax, ay = t.ax, t.ay
                    d = hypot(ax - px, ay - py)
                    units.append(((ax - px) / d, (ay - py) / d))
                    if not t.held:
                        set_max(t.jptr, max(0.0, d - t.w * dt))
                step(space, dt)
                v = get_vel(body)
                vx1, vy1 = v.x, v.y
                p = get_pos(body)
                x, y = p.x, p.y
                n += 1
                if active:
                    mx, my = 0.5 * (vx0 + vx1), 0.5 * (vy0 + vy1)
                    for t, (ux, uy) in zip(active, units):
                        work = impulse(t.jptr) * (ux * mx + uy * my)
                        if work > 0.0:
                            total += work
            if active:
                cx, cy = self._checked_at
                if not hypot(x - cx, y - cy) < self._budget:
                    self.n_substeps_done, self.winch_work_J = n, total
                    self._check_tethers(active)
            vx0, vy0 = vx1, vy1
            if self._next_ready <= n * dt + 1e-9:
                self.n_substeps_done, self.winch_work_J = n, total
                self._activate_ready()
        self.n_substeps_done, self.winch_work_J = n, total

    def _substep_reel(self, active: list[Tether], x: float, y: float, vx0: float, vy0: float) -> None:
        # pymunk moves the bodies first and then solves the joints at the moved positions: the length error it
        # then sees is w dt exactly when the limit is taken from the predicted position
        dt = self.dt_s
        px, py = x + vx0 * dt, y + vy0 * dt
        units = []
        for t in active:
            ax, ay = t.ax, t.ay
            d = math.hypot(ax - px, ay - py)
            units.append(((ax - px) / d, (ay - py) / d))
            if not t.held:
                self._set_max(t, max(0.0, d - t.w * dt))
        self._space_step(dt)
        vx1, vy1 = self._velocity_after()
        mx, my = 0.5 * (vx0 + vx1), 0.5 * (vy0 + vy1)
        fast = self._fast
        for t, (ux, uy) in zip(active, units):
            impulse = _cp.cpConstraintGetImpulse(t.jptr) if fast else t.slide_joint().impulse
            work = impulse * (ux * mx + uy * my)
            if work > 0.0:
                self.winch_work_J += work
