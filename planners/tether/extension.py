"""Polygon extension (Sec. 4.2): every convex piece grows into each neighbour so that neighbours overlap.

Extending piece ``A`` into its neighbour ``B`` across their shared border extends the border lines next to it
into ``B``; the three cases of the text (the lines meet inside ``B``, outside it, or not at all) all give the
same set: ``A`` united with the part of ``B`` inside the half-planes of ``A``'s other edges. For a convex ``A``
whose edge is the whole shared border that union is convex (a segment from ``A`` into that part crosses the
border's line within the border). The thesis's example (Eq. 6-7, Fig. 9-10): the L map's shaft
``x in (0, 5), y in (0, 15)`` and its arm ``x in (5, 20), y in (10, 15)``; the arm extended into the shaft adds
``x in (0, 5), y in (10, 15)``, the shaft extended into the arm adds nothing (the line ``x = 5`` of its lower
edge bounds it), so the overlap of the two regions is ``x in (0, 5), y in (10, 15)``.

A piece with several neighbours gets every extension whose union with what it has stays convex (largest
first); the text does not say what to do when two extensions together break convexity, and a region must be
convex for its mode's invariant to be a conjunction of half-planes (Eq. 6).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import shapely
from shapely.geometry import Polygon

from planners.tether.decomposition import piece_adjacency
from planners.tether.geometry import AREA_EPS_M2, clean

Point = tuple[float, float]


@dataclass
class ExtendedRegion:
    """A convex region of the map: its piece of the decomposition and the piece extended into its neighbours."""

    index: int
    piece: Polygon
    polygon: Polygon
    neighbours: list[int] = field(default_factory=list)


def half_plane(u: np.ndarray, v: np.ndarray, reach_m: float) -> Polygon:
    """The closed half-plane left of the directed line u -> v (inside of a CCW edge), as a big square."""
    d = (v - u) / np.linalg.norm(v - u)
    n = np.array([-d[1], d[0]])
    p0, p1 = u - reach_m * d, u + reach_m * d
    return Polygon([p0, p1, p1 + reach_m * n, p0 + reach_m * n])


def extend_into(a: Polygon, b: Polygon, shared: tuple[Point, Point]) -> Polygon:
    """``a`` extended into ``b`` across the border ``shared``: ``a`` with ``b`` in the half-planes of ``a``'s other
    edges (Sec. 4.2)."""
    coords = np.asarray(shapely.orient_polygons(a).exterior.coords)
    s0, s1 = np.asarray(shared[0]), np.asarray(shared[1])
    x0, y0, x1, y1 = shapely.union(a, b).bounds
    reach = 4.0 * math.hypot(x1 - x0, y1 - y0) + 1.0
    part = b
    for u, v in zip(coords[:-1], coords[1:]):
        if np.linalg.norm(v - u) < 1e-12:
            continue
        if (np.allclose(u, s0) and np.allclose(v, s1)) or (np.allclose(u, s1) and np.allclose(v, s0)):
            continue  # the shared border itself
        part = part.intersection(half_plane(u, v, reach))
        if part.is_empty:
            break
    grown = clean(shapely.union(a, part))
    if grown.geom_type != "Polygon":
        return a
    return shapely.orient_polygons(shapely.simplify(grown, 0.0))


def is_convex_polygon(p: Polygon, tol: float = 1e-9) -> bool:
    return p.convex_hull.area - p.area <= tol * max(1.0, p.area)


def extend_regions(pieces: Sequence[Polygon]) -> list[ExtendedRegion]:
    """Every piece extended into each neighbour it shares a border with (see the module docstring)."""
    regions = [ExtendedRegion(i, p, p) for i, p in enumerate(pieces)]
    grows: dict[int, list[Polygon]] = {i: [] for i in range(len(pieces))}
    for i, j, shared in piece_adjacency(pieces):
        regions[i].neighbours.append(j)
        regions[j].neighbours.append(i)
        grows[i].append(extend_into(pieces[i], pieces[j], shared))
        grows[j].append(extend_into(pieces[j], pieces[i], shared))
    for i, region in enumerate(regions):
        poly = region.piece
        for g in sorted(grows[i], key=lambda q: -q.area):
            if g.area - region.piece.area <= AREA_EPS_M2:
                continue
            cand = clean(shapely.union(poly, g))
            if cand.geom_type == "Polygon" and is_convex_polygon(cand):
                poly = shapely.orient_polygons(shapely.simplify(cand, 0.0))
        region.polygon = poly
    return regions
