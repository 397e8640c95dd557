"""Geometry the tether planners share, on top of shapely: the conservative free space, an anchor's visibility
polygon, its radial cells, and shadows (:func:`shadow_pieces`).

- Free space: the station eroded by the cargo radius (plus a clearance) with mitred joins, INSIDE the exact
  erosion (every plan keeps the disc in the station) and with as many vertices as the station; it gives up
  ``rho^2 (1 - pi / 4)`` at each right-angle notch.
- Visibility: the station polygon minus the shadows its walls cast from the anchor.
- Radial cells: the rays from the anchor through every vertex of the free space it sees cut that space into
  cells which every ray crosses in one interval, so the points one pull brings into a set are computed
  exactly, cell by cell (:mod:`~planners.tether.reachability`).

Why each construction holds: ``docs/planner_design.md#tether-geometry``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import shapely
from shapely.geometry import MultiPolygon, Polygon
from shapely.geometry.base import BaseGeometry

from impact_env.tether.station import Station

AREA_EPS_M2 = 1e-9  # pieces smaller than this are numerical slivers, not regions
_MITRE_LIMIT = 1e6  # never bevel: a bevel at a notch would cut inside the arc
_MAX_WEDGE_RAD = math.pi / 3  # wider wedges are split so that a far point stays far (see shadow)


def free_space_polygon(station: Station, clearance_m: float = 0.0) -> BaseGeometry:
    """The cargo centre's free space, mitred (see the module docstring); a Polygon or MultiPolygon."""
    rho = station.cargo.radius_m + clearance_m
    return station.shapely_polygon.buffer(-rho, join_style="mitre", mitre_limit=_MITRE_LIMIT)


def polygons_of(geom: BaseGeometry) -> list[Polygon]:
    """The polygonal parts of a geometry with more than :data:`AREA_EPS_M2` area (lines and points dropped)."""
    if geom is None or geom.is_empty:
        return []
    return [p for p in shapely.get_parts(geom) if p.geom_type == "Polygon" and p.area > AREA_EPS_M2] if \
        geom.geom_type != "Polygon" else ([geom] if geom.area > AREA_EPS_M2 else [])


def clean(geom: BaseGeometry) -> BaseGeometry:
    """Only the polygonal parts of ``geom`` (an empty Polygon if none)."""
    parts = polygons_of(geom)
    if not parts:
        return Polygon()
    return parts[0] if len(parts) == 1 else MultiPolygon(parts)


def far_distance(station: Station) -> float:
    """A length beyond which nothing of the station lies from any of its points (m)."""
    x0, x1, y0, y1 = station.bounds
    return 4.0 * math.hypot(x1 - x0, y1 - y0) + 1.0


def shadow_pieces(anchor: np.ndarray, seeds: list[BaseGeometry], far_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Polygons whose union with the seeds is their shadow from ``anchor``, and for each the index of its seed.

    Only the edges that face away from the light are needed: a point of the shadow outside a seed lies on a ray
    from the anchor that last leaves the seed through such an edge. A run of consecutive such edges turns
    monotonically about the anchor, so the run and its far image (each vertex pushed ``far_m`` out along its
    ray) bound one simple polygon: one piece per run. All pieces are built in one call.
    """
    a = np.asarray(anchor, dtype=float)
    rings, owner_of_ring = [], []
    for k, seed in enumerate(seeds):
        for p in polygons_of(seed):
            ext = np.asarray(p.exterior.coords)
            rings.append(ext if p.exterior.is_ccw else ext[::-1])  # outward normal on the right of each edge
            owner_of_ring.append(k)
            for hole in p.interiors:
                c = np.asarray(hole.coords)
                rings.append(c[::-1] if hole.is_ccw else c)
                owner_of_ring.append(k)
    if not rings:
        return np.array([], dtype=object), np.zeros(0, dtype=int)
    lengths = np.array([len(r) for r in rings])
    V = np.concatenate(rings)
    starts = np.concatenate([[0], np.cumsum(lengths)[:-1]])
    R = V - a
    F = V + far_m * R / np.sqrt((R * R).sum(axis=1))[:, None]
    d = np.roll(V, -1, axis=0) - V  # edge i runs from vertex i to i + 1 (the last of each ring is its closure)
    mid = V + 0.5 * d - a
    away = (d[:, 1] * mid[:, 0] - d[:, 0] * mid[:, 1]) > 1e-12
    idx_parts, ring_offsets, owners = [], [0], []
    total = 0
    for start, n, k in zip(starts, lengths, owner_of_ring):
        m = n - 1  # edges of the ring
        mask = away[start: start + m]
        if not mask.any():
            continue
        if mask.all():
            runs = [np.arange(m)]
        else:
            first = int(np.flatnonzero(~mask)[0])
            order = (np.arange(m) + first) % m
            flags = mask[order]
            cuts = np.flatnonzero(np.diff(np.concatenate([[0], flags.astype(np.int8), [0]])))
            runs = [order[b:e] for b, e in zip(cuts[::2], cuts[1::2])]
        for run in runs:
            chain = start + np.concatenate([run, [(run[-1] + 1) % m]])
            # vertices of the chain, then their far images backward, closed: indices into V (near) and F (far)
            idx_parts.append(np.concatenate([chain, len(V) + chain[::-1], chain[:1]]))
            total += 2 * len(chain) + 1
            ring_offsets.append(total)
            owners.append(k)
    if not idx_parts:
        return np.array([], dtype=object), np.zeros(0, dtype=int)
    coords = np.concatenate([V, F])[np.concatenate(idx_parts)]
    offsets = np.asarray(ring_offsets)
    polys = shapely.from_ragged_array(shapely.GeometryType.POLYGON, coords, (offsets, np.arange(len(offsets))))
    return polys, np.asarray(owners)


def visibility_polygon(station: Station, anchor_index: int) -> BaseGeometry:
    """The points of the station from which a tether reaches anchor ``anchor_index`` (Polygon, possibly Multi)."""
    a = station.anchor_positions[anchor_index]
    far = far_distance(station)
    walls = np.asarray(station.walls, dtype=float)  # (n, 2, 2)
    p, q = walls[:, 0], walls[:, 1]
    cross = (p[:, 0] - a[0]) * (q[:, 1] - a[1]) - (p[:, 1] - a[1]) * (q[:, 0] - a[0])
    # walls through the anchor (its own) cast no shadow; every other wall may (also those whose outer side faces
    # the anchor: a segment that leaves through the anchor's own wall re-enters the station through them)
    keep = np.abs(cross) > 1e-12
    blockers = []
    for pi, qi in zip(p[keep], q[keep]):
        # split wide walls so that every shadow quadrilateral spans less than 60 degrees
        ang = _angle_between(pi - a, qi - a)
        parts = max(1, math.ceil(ang / _MAX_WEDGE_RAD))
        for k in range(parts):
            s0, s1 = pi + (qi - pi) * k / parts, pi + (qi - pi) * (k + 1) / parts
            d0, d1 = s0 - a, s1 - a
            blockers.append([s0, s1, s1 + far * d1 / np.linalg.norm(d1), s0 + far * d0 / np.linalg.norm(d0), s0])
    if not blockers:
        return station.shapely_polygon
    shadows = shapely.polygons(np.asarray(blockers))
    shadows = shadows[shapely.area(shadows) > 0]
    return clean(station.shapely_polygon.difference(shapely.union_all(shadows)))


def _angle_between(u: np.ndarray, v: np.ndarray) -> float:
    return abs(math.atan2(u[0] * v[1] - u[1] * v[0], u[0] * v[0] + u[1] * v[1]))


@dataclass
class RadialCells:
    """The radial cells of the free space seen from one anchor (see the module docstring).

    ``near`` marks the cells that reach into the stop disc (a pull cannot end there), ``disc`` is the disc
    (circumscribed polygon: it contains the true disc, so no kept point is inside the stop radius).
    """

    anchor: int
    position_m: np.ndarray
    region: BaseGeometry  # free space seen from the anchor
    cells: np.ndarray  # shapely Polygons
    disc: Polygon
    near: np.ndarray  # bool per cell


WEDGE_GAP_RAD = 1e-9  # wedges stop this short of the rays through vertices (see radial_cells)


def radial_cells(station: Station, anchor_index: int, free: BaseGeometry, stop_radius_m: float,
                 region: BaseGeometry | None = None) -> RadialCells:
    """Cut the free space that anchor ``anchor_index`` sees into radial cells.

    The wedges between consecutive rays through the vertices stop :data:`WEDGE_GAP_RAD` short of those rays: a
    notch of the free space on a wedge's side ray would otherwise glue two cells at a point (two intervals of
    the same ray in one cell). The rays themselves (zero area) belong to no cell; the planner allows for that
    with a tolerance of a micrometre when it asks whether a point is in a level.
    """
    a = station.anchor_positions[anchor_index]
    far = far_distance(station)
    quad_segs = 16
    disc = shapely.Point(a).buffer(stop_radius_m / math.cos(math.pi / (4 * quad_segs)), quad_segs=quad_segs)
    if region is None:
        region = seen_free_space(station, anchor_index, free)
    empty = np.array([], dtype=object)
    if region.is_empty:
        return RadialCells(anchor_index, a, region, empty, disc, np.zeros(0, dtype=bool))
    coords = _turning_vertices(region, a)
    d = coords - a
    # angles about the anchor's inward direction, so that the seen region never straddles the cut at +-pi
    ref = _inward(station, anchor_index)
    ang = np.arctan2(ref[0] * d[:, 1] - ref[1] * d[:, 0], ref[0] * d[:, 0] + ref[1] * d[:, 1])
    ang = np.unique(np.round(ang, 12))
    lo_list, hi_list = [], []
    for lo, hi in zip(ang[:-1], ang[1:]):
        if hi - lo <= 2.5 * WEDGE_GAP_RAD:
            continue
        parts = max(1, math.ceil((hi - lo) / _MAX_WEDGE_RAD))
        cuts = lo + (hi - lo) * np.arange(parts + 1) / parts
        lo_list.extend(cuts[:-1])
        hi_list.extend(cuts[1:])
    lo_arr = np.asarray(lo_list)
    hi_arr = np.asarray(hi_list)
    # only the rays through vertices need the gap; the extra cuts of wide wedges are not through any vertex
    at_vertex_lo = np.isin(lo_arr, ang)
    at_vertex_hi = np.isin(hi_arr, ang)
    base = math.atan2(ref[1], ref[0])
    th0 = base + lo_arr + np.where(at_vertex_lo, WEDGE_GAP_RAD, 0.0)
    th1 = base + hi_arr - np.where(at_vertex_hi, WEDGE_GAP_RAD, 0.0)
    wedges = np.stack([np.broadcast_to(a, (len(th0), 2)),
                       a + far * np.stack([np.cos(th0), np.sin(th0)], axis=1),
                       a + far * np.stack([np.cos(th1), np.sin(th1)], axis=1),
                       np.broadcast_to(a, (len(th0), 2))], axis=1)
    pieces = shapely.intersection(shapely.polygons(wedges), region)
    cells = np.array([c for piece in pieces for c in polygons_of(piece)], dtype=object)
    near = shapely.intersects(cells, disc) if len(cells) else np.zeros(0, dtype=bool)
    return RadialCells(anchor_index, a, region, cells, disc, np.asarray(near, dtype=bool))


def seen_free_space(station: Station, anchor_index: int, free: BaseGeometry) -> BaseGeometry:
    """The part of the free space from which a tether reaches the anchor."""
    return clean(free.intersection(visibility_polygon(station, anchor_index)))


def _turning_vertices(region: BaseGeometry, a: np.ndarray) -> np.ndarray:
    """The vertices where the boundary turns back as seen from ``a`` (both neighbours on one side of the ray
    through it): only there can a ray's intersection with the region split or merge."""
    out = []
    for p in polygons_of(region):
        for ring in (p.exterior, *p.interiors):
            c = np.asarray(ring.coords)[:-1]
            prev, nxt = np.roll(c, 1, axis=0), np.roll(c, -1, axis=0)
            r = c - a
            s0 = r[:, 0] * (prev[:, 1] - c[:, 1]) - r[:, 1] * (prev[:, 0] - c[:, 0])
            s1 = r[:, 0] * (nxt[:, 1] - c[:, 1]) - r[:, 1] * (nxt[:, 0] - c[:, 0])
            scale = 1e-12 * (1.0 + np.abs(r).sum(axis=1)) ** 2
            # same side, or an edge along the ray (then the vertex ends or starts a radial stretch of boundary)
            turning = (s0 * s1 > 0) | (np.abs(s0) <= scale) | (np.abs(s1) <= scale)
            out.append(c[turning])
    return np.concatenate(out) if out else np.zeros((0, 2))


def _inward(station: Station, anchor_index: int) -> np.ndarray:
    """Unit vector from the anchor into the station: the inward normal of its wall (bisector at a corner)."""
    anchor = station.anchors[anchor_index]
    (x0, y0), (x1, y1) = station.walls[anchor.wall]
    ex, ey = x1 - x0, y1 - y0
    n = np.array([-ey, ex]) / math.hypot(ex, ey)  # left of a CCW wall = inside
    pos = np.asarray(anchor.position_m)
    nv = len(station.polygon)
    ends = (((x0, y0), station.walls[(anchor.wall - 1) % nv]), ((x1, y1), station.walls[(anchor.wall + 1) % nv]))
    for end, other in ends:
        if math.dist(end, pos) < 1e-9:  # an anchor on a corner: the bisector of the two walls' normals
            (u0, v0), (u1, v1) = other
            m = np.array([-(v1 - v0), u1 - u0]) / math.hypot(u1 - u0, v1 - v0)
            s = n + m
            return s / np.linalg.norm(s) if np.linalg.norm(s) > 1e-9 else n
    return n


def pull_segment(station: Station, free: BaseGeometry, start: np.ndarray, anchor_index: int,
                 stop_radius_m: float) -> np.ndarray | None:
    """Where a pull toward the anchor can carry the cargo from ``start``: the segment ``[start, end]`` (2x2) up to
    the first exit from the free space or the stop radius; None if the anchor is out of sight or too close."""
    a = station.anchor_positions[anchor_index]
    x = np.asarray(start, dtype=float)
    dist = float(np.linalg.norm(a - x))
    if dist <= stop_radius_m or not station.line_of_sight(x, [anchor_index])[0]:
        return None
    u = (a - x) / dist
    stop = x + (dist - stop_radius_m) * u
    line = shapely.LineString([x, stop])
    inside = line.intersection(free)
    if inside.is_empty:
        return None
    pt = shapely.Point(x)
    parts = [g for g in shapely.get_parts(inside) if g.geom_type == "LineString" and g.length > 0]
    parts = [g for g in parts if g.distance(pt) < 1e-9]
    if not parts:
        return None
    far_end = max((np.asarray(c) for g in parts for c in g.coords), key=lambda c: float(np.dot(c - x, u)))
    return np.array([x, far_end])
