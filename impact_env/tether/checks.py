"""The tether world's geometry checks each substep: tethers that arrive or snag, and a kinematic cargo at a wall.

A pulling tether is released when the cargo centre comes within the stop radius of its anchor (``"arrived"``)
and when a wall comes between the cargo centre and its anchor (``"snagged"``). Both exact tests are skipped while
the cargo provably cannot have changed their outcome (``cache_checks``): the budget of :meth:`_check_tethers`
and the notch clearance of :mod:`impact_env.tether.sight`. Without inertia (``kinematic``) the cargo is moved
by Eq. (5), which knows no walls: :meth:`_slide_along_walls` drops the velocity into a wall it touches.
"""

from __future__ import annotations

import math

import numpy as np

from impact_env.tether.sight import distance_to_rays, shadow_rays
from impact_env.tether.stepping import CHECK_MARGIN_M, SLOP_M, SubstepBase, Tether


class TetherChecks(SubstepBase):
    """The checks of :class:`~impact_env.tether.physics.TetherWorld` (see the module docstring)."""

    def _slide_along_walls(self, x: float, y: float, vx: float, vy: float) -> tuple[float, float]:
        """Eq. (5) without inertia meets a wall: drop the velocity component into each wall the cargo touches.

        The cargo then slides along the wall (no friction) instead of being driven into it every substep, which
        pymunk's contacts would only undo a step later.
        """
        sx, sy = self._wall_seen_at
        if self._cache and math.hypot(x - sx, y - sy) < self._wall_margin:
            return vx, vy  # farther from every wall than the cargo has moved since they were measured
        rel = np.array([x, y]) - self._wall_a
        s = np.clip(np.einsum("ij,ij->i", rel, self._wall_e) / self._wall_ee, 0.0, 1.0)
        away = rel - s[:, None] * self._wall_e  # from the nearest wall point to the centre
        dist = np.hypot(away[:, 0], away[:, 1])
        reach = self.station.cargo.radius_m + 2.0 * SLOP_M
        self._wall_seen_at, self._wall_margin = (x, y), float(dist.min()) - reach
        touching = np.flatnonzero(dist <= reach)
        for _ in range(2):  # two passes settle a corner (two walls)
            for i in touching:
                nx, ny = away[i] / dist[i]
                into = -(vx * nx + vy * ny)
                if into > 0.0:
                    vx, vy = vx + into * nx, vy + into * ny
        return float(vx), float(vy)  # numpy's scalars would carry into the winch work and the info

    def _check_tethers(self, active: list[Tether]) -> None:
        """Release tethers inside their stop radius ("arrived") and those a wall has come across ("snagged").

        A visible tether can only lose its line of sight when the segment from the cargo to the anchor sweeps
        over a notch (a reflex vertex): touching an edge's inside, or a convex corner, from the interior means
        crossing it, so the first contact is at a notch, and the segment passes through a notch exactly when the
        cargo is on the ray from the anchor through that notch, beyond it. So while the cargo stays closer to
        where it was last tested exactly than to any such ray, the tether is still in sight and the shapely test
        is skipped. One budget covers every pulling tether: how far the cargo may move before any tether could
        reach its stop radius or need an exact test, so most substeps check one distance.
        """
        x, y = self.state()[:2]
        cx, cy = self._checked_at
        if math.hypot(x - cx, y - cy) < self._budget:
            return
        held, exact = [], []
        for robot, t in enumerate(self._tethers):
            if t is None or not t.pulling:
                continue
            ax, ay = t.ax, t.ay
            if (ax - x) ** 2 + (ay - y) ** 2 <= self._stop2:
                self.release(robot, "arrived")
                continue
            sx, sy = t.seen_at
            if not (self._cache and math.hypot(x - sx, y - sy) < t.clearance):
                held.append((robot, t))
                exact.append(t.anchor)
        if held:
            for (robot, t), visible in zip(held, self.station.sees(x, y, exact)):
                if not visible:
                    self.release(robot, "snagged")
                elif self._cache:
                    t.seen_at, t.clearance = (x, y), self._notch_clearance(x, y, t.anchor)
        self._checked_at = (x, y)
        budget = math.inf if self._cache else -1.0
        for t in self._tethers:
            if t is not None and t.pulling and budget > 0.0:
                sx, sy = t.seen_at
                stop = math.hypot(t.ax - x, t.ay - y) - self._stop
                sight = t.clearance - math.hypot(x - sx, y - sy)
                budget = min(budget, stop, sight)
        self._budget = budget - CHECK_MARGIN_M

    def _notch_clearance(self, x: float, y: float, anchor: int) -> float:
        """How far (m) the cargo may move from (x, y) before its tether to ``anchor`` could touch a notch: the
        distance to the rays from the notches away from the anchor (:mod:`impact_env.tether.sight`)."""
        if anchor in self._notch_rays:
            rays = self._notch_rays[anchor]
        else:
            rays = self._notch_rays[anchor] = shadow_rays(np.asarray(self._anchors[anchor]), self._notches)
        return distance_to_rays(x, y, rays)
