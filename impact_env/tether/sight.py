"""The line-of-sight mask of every anchor from the cargo, cached while the cargo cannot have changed it.

The exact test (:meth:`Station.line_of_sight`, a shapely ``covers`` of one segment per anchor) costs more than
a control step of the physics, and the environments need the whole mask every step. Whether the segment from
a point inside the station to an anchor on its boundary leaves the station changes only when the segment
sweeps over a vertex of the polygon: it meets the boundary transversally or not at all, and moving from one
to the other means touching it first, which a segment from an interior point to a boundary point can do only
at a vertex (a point inside the anchor's own wall is never touched from inside, and a cargo centre on the
line of that wall makes the segment pass through the wall's end vertex). Every point of the segment moves at
most as far as its cargo end, so while the cargo stays within the segment's distance to the nearest vertex,
measured at the last exact test, the anchor's entry of the mask is unchanged. :class:`SightCache` keeps one
such radius for the whole mask (the smallest over the anchors) and recomputes exactly when the cargo leaves
it: the same masks as the exact test, bit for bit (``tests/test_tether_sight.py``).
"""

from __future__ import annotations

import math

import numpy as np

from impact_env.tether.station import Station

MARGIN_M = 1e-7  # the cache ends this much before the distance it relies on (the exact test's 1 nm and rounding)


class SightCache:
    """``mask(x, y)``: :meth:`Station.line_of_sight` of every anchor, recomputed only when it may have changed.

    A station with an anchor on a vertex of its polygon is never cached (that anchor's segments touch it).
    """

    def __init__(self, station: Station) -> None:
        self.station = station
        self._anchors = station.anchor_positions
        vertices = np.array(station.polygon, dtype=float)
        self._vertices = vertices
        self._seen_at = (math.nan, math.nan)
        self._radius = -1.0
        self._mask = np.zeros(station.n_anchors, dtype=bool)
        self.exact_tests = 0

    def mask(self, x: float, y: float) -> np.ndarray:
        """The line-of-sight mask from the cargo centre (x, y) (bool, n_anchors; do not modify it)."""
        sx, sy = self._seen_at
        if math.hypot(x - sx, y - sy) < self._radius:
            return self._mask
        self._mask = self.station.line_of_sight((x, y))
        self.exact_tests += 1
        self._seen_at = (x, y)
        self._radius = self._clearance(x, y) - MARGIN_M
        return self._mask

    def _clearance(self, x: float, y: float) -> float:
        """The smallest distance (m) from a segment (x, y) -> anchor to a vertex of the polygon (inf if none)."""
        a, v = self._anchors, self._vertices
        if not len(a):
            return math.inf
        ex, ey = a[:, 0] - x, a[:, 1] - y  # (n_anchors,)
        rx, ry = v[None, :, 0] - x, v[None, :, 1] - y  # (1, n_vertices)
        ee = ex * ex + ey * ey
        s = np.clip((rx * ex[:, None] + ry * ey[:, None]) / np.maximum(ee, 1e-300)[:, None], 0.0, 1.0)
        return float(np.hypot(rx - s * ex[:, None], ry - s * ey[:, None]).min())
