"""The ``force`` fidelity's substep loop: a saturating winch tension along each tether.

A tension ``T_i = F_max * clip(1 - v_r,i / w, 0, 1)`` along each reeling tether, ``v_r,i`` the
cargo's speed toward anchor ``i``: full winch force from rest, none once the cargo approaches at ``w``. One
tether from rest: ``v_n = w (1 - (1 - g)^n)`` after ``n`` substeps, ``g = dt F_max / (m w)`` (pymunk's
semi-implicit Euler step); continuous time constant ``m w / F_max``. Several tethers settle where no tether
pulls, as in ``reel`` (each distance shrinking at ``w``). A held tether is the same speed control with the
set point 0: ``T = F_max * clip(-v_r / w, 0, 1)``, a brake that stops a cargo moving away from the anchor
with the time constant ``m w / F_max``.

The winch work is ``T dt`` times the substep's mean speed toward the anchor, the positive parts summed. Two
paths, bit-identical: written out with chipmunk's C functions (:meth:`_step_force_fast`) and through pymunk's
public API (:meth:`_substep_force`).
"""

from __future__ import annotations

import math

from impact_env.tether.checks import TetherChecks
from impact_env.tether.stepping import Tether
from impact_env.tether.stepping import chipmunk_lib as _cp


class ForceLoop(TetherChecks):
    """The force substeps of :class:`~impact_env.tether.physics.TetherWorld`."""

    def _step_force_fast(self) -> None:
        cp, body, space, dt, hypot = _cp, self._body_ptr, self._space_ptr, self.dt_s, math.hypot
        get_pos, get_vel, set_force = cp.cpBodyGetPosition, cp.cpBodyGetVelocity, cp.cpBodySetForce
        step = cp.cpSpaceStep
        winch = self._winch_N
        x, y, vx0, vy0 = self._begin_fast()
        for _ in range(self.substeps):
            active = self._active
            if active is None:
                active = self._active = [t for t in self._tethers if t is not None and t.pulling]
                self._budget = -1.0
            fx = fy = 0.0
            tensions = []
            for t in active:
                ax, ay = t.ax, t.ay
                d = hypot(ax - x, ay - y)
                ux, uy = (ax - x) / d, (ay - y) / d
                shortfall = (0.0 if t.held else 1.0) - (vx0 * ux + vy0 * uy) / t.w
                tension = winch * (0.0 if shortfall < 0.0 else (1.0 if shortfall > 1.0 else shortfall))
                tensions.append((tension, ux, uy))
                fx += tension * ux
                fy += tension * uy
            set_force(body, (fx, fy))
            step(space, dt)
            v = get_vel(body)
            vx1, vy1 = v.x, v.y
            if active:
                mx, my = 0.5 * (vx0 + vx1), 0.5 * (vy0 + vy1)
                for tension, ux, uy in tensions:
                    work = tension * dt * (ux * mx + uy * my)
                    if work > 0.0:
                        self.winch_work_J += work
            self.n_substeps_done += 1
            p = get_pos(body)
            x, y, vx0, vy0 = p.x, p.y, vx1, vy1
            self._after_substep_fast(active, x, y)

    def _substep_force(self, active: list[Tether], x: float, y: float, vx0: float, vy0: float) -> None:
        dt = self.dt_s
        fx = fy = 0.0
        tensions = []
        for t in active:
            ax, ay = t.ax, t.ay
            d = math.hypot(ax - x, ay - y)
            ux, uy = (ax - x) / d, (ay - y) / d
            # a held winch is the same speed control with the set point 0
            shortfall = (0.0 if t.held else 1.0) - (vx0 * ux + vy0 * uy) / t.w
            tension = self._winch_N * (0.0 if shortfall < 0.0 else (1.0 if shortfall > 1.0 else shortfall))
            tensions.append((tension, ux, uy))
            fx += tension * ux
            fy += tension * uy
        if self._fast:
            _cp.cpBodySetForce(self._body_ptr, (fx, fy))
        else:
            self.cargo.force = (fx, fy)
        self._space_step(dt)
        vx1, vy1 = self._velocity_after()
        mx, my = 0.5 * (vx0 + vx1), 0.5 * (vy0 + vy1)
        for tension, ux, uy in tensions:
            work = tension * dt * (ux * mx + uy * my)
            if work > 0.0:
                self.winch_work_J += work
