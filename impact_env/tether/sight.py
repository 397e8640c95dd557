"""The line-of-sight mask of every anchor from the cargo, cached while the cargo cannot have changed it.

The exact test (:meth:`Station.line_of_sight`, a shapely ``covers`` of one segment per anchor) costs more than
a control step of the physics, and the environments need the whole mask every step. Whether the segment from
a point ``x`` inside the station to an anchor ``a`` on its boundary leaves the station can only change when
the segment passes through a notch (a reflex vertex) or ``x`` crosses the line of the anchor's own wall. The
set of ``x`` that see ``a`` is closed, and open except where the segment touches the boundary away from ``a``:
touching a wall's inside from the interior means running along it, and a segment through a convex corner
leaves the station on one side of it, so the touch is at a notch; a cargo centre on the line of the anchor's
wall makes the segment pass through that wall's end. The segment contains such a point ``v`` exactly when
``x`` lies on the ray from ``a`` through ``v``, beyond ``v`` (an anchor on a vertex is tested exactly every
time). So the mask entry of ``a`` is unchanged while the cargo stays closer to
its last exactly tested position than to any of ``a``'s rays: :class:`SightCache` keeps that radius per anchor,
tests exactly only the anchors whose radius the cargo has left, and skips even that check while the cargo is
within the smallest remaining radius of all. The masks are those of the exact test, bit for bit
(``tests/impact_env/tether/test_fast_path.py``). The tethers' snag check uses the same bound over the notches
only (a visible tether can lose sight only at a reflex vertex).
"""

from __future__ import annotations

import math

import numpy as np
import shapely

from impact_env.tether.station import Station

MARGIN_M = 1e-7  # a radius ends this much early (the exact test's 1 nm tolerance, and rounding)


def shadow_rays(anchor: np.ndarray, points: np.ndarray) -> list[tuple[float, float, float, float]] | None:
    """The rays on which a segment from a cargo centre to ``anchor`` passes through one of ``points``, as
    (origin x, origin y, unit direction x, y): from each point away from the anchor. None when the anchor sits on
    one of the points (its segments always touch it: no radius holds)."""
    ax, ay = float(anchor[0]), float(anchor[1])
    rays = []
    for vx, vy in np.asarray(points, dtype=float).reshape(-1, 2):
        d = math.hypot(vx - ax, vy - ay)
        if d <= 1e-9:
            return None
        rays.append((float(vx), float(vy), (vx - ax) / d, (vy - ay) / d))
    return rays


def distance_to_rays(x: float, y: float, rays: list[tuple[float, float, float, float]] | None) -> float:
    """The smallest distance (m) from (x, y) to the rays (inf without rays, 0 for None)."""
    if rays is None:
        return 0.0
    best = math.inf
    for ox, oy, dx, dy in rays:
        px, py = x - ox, y - oy
        t = px * dx + py * dy
        if t > 0.0:
            px, py = px - t * dx, py - t * dy
        d = math.hypot(px, py)
        if d < best:
            best = d
    return best


class SightCache:
    """``mask(x, y)``: :meth:`Station.line_of_sight` of every anchor, re-tested only where it may have changed.

    Per anchor it keeps a lower bound on the distance from the reference point to the anchor's rays. While the
    cargo stays within the smallest of them nothing can have changed. Past it, an anchor whose bound the cargo
    has left is checked against the last move (from the previous point, where the mask is known, to the new
    one): a move that crosses none of its rays leaves its entry as it was, and only a move that crosses one (or
    a move too long to be a straight path inside the station) is tested exactly.
    """

    def __init__(self, station: Station) -> None:
        self.station = station
        polygon = np.array(station.polygon, dtype=float)
        self._rays: list[list[tuple[float, float, float, float]] | None] = []
        for a in station.anchors:
            position = np.asarray(a.position_m, dtype=float)
            if np.hypot(polygon[:, 0] - position[0], polygon[:, 1] - position[1]).min() <= 1e-9:
                self._rays.append(None)  # an anchor on a vertex: always tested exactly
                continue
            ends = polygon[[a.wall, (a.wall + 1) % len(polygon)]]
            self._rays.append(shadow_rays(position, np.concatenate([station.notches, ends])))
        self._points = station.anchor_points
        self._sight_polygon = station._sight_polygon
        self._longest_move = 1.9 * station.cargo.radius_m  # a straight move this short stays inside the station
        n = station.n_anchors
        self._mask = np.zeros(n, dtype=bool)
        self._slack = [-1.0] * n  # per anchor: no ray of it within this distance of the reference point
        self._ref = (math.nan, math.nan)
        self._last = (math.nan, math.nan)  # the previous point asked for (its mask is known)
        self._calm = -1.0  # min of the slacks
        self.exact_tests = 0  # anchors tested exactly (for the tests and the benchmark)
        self.version = 0  # counts the calls that may have changed the mask
        self._snapshots: dict[tuple[float, float], tuple] = {}

    def restart(self, x: float, y: float) -> np.ndarray:
        """The mask at an episode's start (x, y): a jump, so the state kept for that point is restored when the
        cache has been there before (the stations' fixed start), and kept for next time otherwise."""
        kept = self._snapshots.get((x, y))
        if kept is not None:
            mask, slack = kept
            self._mask[:] = mask
            self._slack = list(slack)
            self._ref = self._last = (x, y)
            self._calm = min(self._slack) if self._slack else math.inf
            self.version += 1
            return self._mask
        self._last = (math.nan, math.nan)  # a jump: no straight move from the previous point
        self.mask(x, y)
        if len(self._snapshots) < 8:
            self._snapshots[(x, y)] = (self._mask.copy(), tuple(self._slack))
        return self._mask

    def mask(self, x: float, y: float) -> np.ndarray:
        """The line-of-sight mask from the cargo centre (x, y) (bool, n_anchors; updated in place by later calls)."""
        rx, ry = self._ref
        moved = math.hypot(x - rx, y - ry)
        if moved < self._calm:
            self._last = (x, y)
            return self._mask
        lx, ly = self._last
        step_ok = math.hypot(x - lx, y - ly) < self._longest_move  # NaN (first call) is not ok
        slack, rays_of = self._slack, self._rays
        exact = []
        for i in range(len(slack)):
            if moved < slack[i]:
                slack[i] -= moved
                continue
            rays = rays_of[i]
            if rays is None or not step_ok or _crosses(lx, ly, x, y, rays):
                exact.append(i)
            slack[i] = distance_to_rays(x, y, rays) - MARGIN_M
        self.version += 1
        if exact:
            points = self._points
            self._mask[exact] = shapely.covers(self._sight_polygon,
                                               shapely.linestrings([[points[i], (x, y)] for i in exact]))
            self.exact_tests += len(exact)
        self._ref = self._last = (x, y)
        self._calm = min(slack) if slack else math.inf
        return self._mask


def _crosses(x0: float, y0: float, x1: float, y1: float, rays: list) -> bool:
    """Whether the segment (x0, y0) -> (x1, y1) meets one of the rays (within MARGIN_M)."""
    ex, ey = x1 - x0, y1 - y0
    for ox, oy, dx, dy in rays:
        # side of each end against the ray's line, then where the segment meets the line along the ray
        s0 = (x0 - ox) * dy - (y0 - oy) * dx
        s1 = (x1 - ox) * dy - (y1 - oy) * dx
        if (s0 > MARGIN_M and s1 > MARGIN_M) or (s0 < -MARGIN_M and s1 < -MARGIN_M):
            continue
        if abs(s0) <= MARGIN_M and abs(s1) <= MARGIN_M:
            return True  # along the ray's line: let the exact test decide
        u = s0 / (s0 - s1)
        px, py = x0 + u * ex - ox, y0 + u * ey - oy
        if px * dx + py * dy >= -MARGIN_M:
            return True
    return False
