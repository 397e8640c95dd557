"""Convex polygons and their signed distance, the spatial robustness of "point in region".

Positive inside, negative outside, zero on the boundary; the magnitude is the Euclidean distance to the
boundary. Inside a convex polygon that distance is the smallest distance to an edge's supporting line
(the half-space form ``H x <= b`` the planner also uses); outside it is the distance to the nearest edge
segment, which is what a user means by "how far from the region" (the half-space maximum would
underestimate it near corners).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from impact_env.errors import ScenarioError

MAX_COORDINATE_M = 1e6  # |x|, |y| of every vertex; beyond it squared edge lengths lose all precision
# an edge of the scalar fast path: start (vx, vy), vector (ex, ey), outward normal (nx, ny), offset, squared length
Edge = tuple[float, float, float, float, float, float, float, float]
MIN_EXTENT_M = 1e-6  # width and height of a box; a thinner one has edges whose squared length underflows


@dataclass(frozen=True, eq=False)
class ConvexPolygon:
    """A convex polygon given by its vertices in counter-clockwise order, metres.

    Build one with :meth:`from_box` or :meth:`from_vertices` (which validates and orders the vertices).
    Two polygons are equal when their vertex arrays are, so a polygon (and a Scenario) can be hashed.
    """

    vertices: np.ndarray  # (n, 2), counter-clockwise, no repeated closing vertex
    normals: np.ndarray = field(init=False, repr=False)  # (n, 2) outward unit normals of edges i -> i+1
    offsets: np.ndarray = field(init=False, repr=False)  # (n,) so that normals @ x <= offsets inside

    def __post_init__(self) -> None:
        v = np.array(self.vertices, dtype=float)
        v.setflags(write=False)  # shared by the hash, the fast paths and the planner: never edited in place
        edges = np.roll(v, -1, axis=0) - v
        lengths = np.hypot(edges[:, 0], edges[:, 1])
        normals = np.stack([edges[:, 1], -edges[:, 0]], axis=1) / lengths[:, None]
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "normals", normals)
        object.__setattr__(self, "offsets", np.einsum("ij,ij->i", normals, v))

    @cached_property
    def _box(self) -> tuple[float, float, float, float] | None:
        """(xmin, xmax, ymin, ymax) of an axis-aligned box (most regions: a closed-form scalar path), else None."""
        v = self.vertices
        if len(v) == 4:
            xs, ys = sorted(set(np.round(v[:, 0], 15))), sorted(set(np.round(v[:, 1], 15)))
            if len(xs) == 2 and len(ys) == 2:
                return (float(xs[0]), float(xs[1]), float(ys[0]), float(ys[1]))
        return None

    @cached_property
    def _edges_py(self) -> list[Edge]:
        """Plain-float copies for the scalar fast path used once per control step: per edge i -> i+1, its start
        (vx, vy), its vector (ex, ey), its outward normal (nx, ny), its offset and its squared length."""
        v = self.vertices
        edges = np.roll(v, -1, axis=0) - v
        lengths = np.hypot(edges[:, 0], edges[:, 1])
        normals = self.normals
        return [(float(v[i, 0]), float(v[i, 1]), float(edges[i, 0]), float(edges[i, 1]),
                 float(normals[i, 0]), float(normals[i, 1]), float(self.offsets[i]), float(lengths[i]) ** 2)
                for i in range(len(v))]

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, ConvexPolygon):
            return NotImplemented
        return self.vertices.shape == other.vertices.shape and bool(np.array_equal(self.vertices, other.vertices))

    def __hash__(self) -> int:
        return hash((self.vertices.shape, self.vertices.tobytes()))

    @classmethod
    def from_box(cls, xmin: float, xmax: float, ymin: float, ymax: float, where: str = "box") -> ConvexPolygon:
        """Axis-aligned box [xmin, xmax] x [ymin, ymax]."""
        _check_coordinates(np.array([[xmin, ymin], [xmax, ymax]], dtype=float), where)
        if not (xmin < xmax and ymin < ymax):
            raise ScenarioError(f"{where} must have xmin < xmax and ymin < ymax, "
                                f"got [{xmin}, {xmax}] x [{ymin}, {ymax}]")
        if not (xmax - xmin >= MIN_EXTENT_M and ymax - ymin >= MIN_EXTENT_M):
            raise ScenarioError(f"{where} must be at least {MIN_EXTENT_M:g} m wide and high, "
                                f"got {xmax - xmin:g} m x {ymax - ymin:g} m")
        return cls(np.array([[xmin, ymin], [xmax, ymin], [xmax, ymax], [xmin, ymax]], dtype=float))

    @classmethod
    def from_vertices(cls, vertices: np.ndarray | list, where: str = "polygon") -> ConvexPolygon:
        """Validate a vertex list (either orientation) and return the counter-clockwise polygon.

        Repeated consecutive vertices, including a last vertex that repeats the first (a "closed" ring, as
        GeoJSON and shapely write it), are dropped. The rest must be a simple convex polygon: every turn
        in the same direction and one full turn in all, so a self-intersecting star, whose turns also all
        go one way, is rejected.
        """
        try:
            v = np.asarray(vertices, dtype=float)
        except (TypeError, ValueError):
            raise ScenarioError(f"{where} must be a list of [x, y] vertices") from None
        if v.ndim != 2 or v.shape[1] != 2:
            raise ScenarioError(f"{where} needs at least 3 vertices [x, y], got shape {v.shape}")
        if not np.all(np.isfinite(v)):
            raise ScenarioError(f"{where} has non-finite coordinates")
        _check_coordinates(v, where)
        v = _drop_repeats(v)
        if len(v) < 3:
            raise ScenarioError(f"{where} needs at least 3 distinct vertices [x, y], got {len(v)}")
        scale = float(np.ptp(v, axis=0).max())
        area2 = float(np.sum(v[:, 0] * np.roll(v[:, 1], -1) - np.roll(v[:, 0], -1) * v[:, 1]))
        if abs(area2) <= 1e-12 * max(scale * scale, 1.0):
            raise ScenarioError(f"{where} has zero area")
        if area2 < 0:
            v = v[::-1].copy()
        edges = np.roll(v, -1, axis=0) - v
        nxt = np.roll(edges, -1, axis=0)
        cross = edges[:, 0] * nxt[:, 1] - edges[:, 1] * nxt[:, 0]
        dot = np.einsum("ij,ij->i", edges, nxt)
        lengths = np.hypot(edges[:, 0], edges[:, 1])
        # a turn is the signed angle between consecutive edges; a convex polygon turns left (or goes straight)
        # at every vertex and turns exactly once around in all (a pentagram turns twice)
        turns = np.arctan2(cross, dot)
        if np.any(cross < -1e-12 * lengths * np.roll(lengths, -1)) or np.any(turns < -1e-9):
            raise ScenarioError(f"{where} is not convex; split it into convex pieces")
        if abs(float(turns.sum()) - 2.0 * math.pi) > 1e-6:
            raise ScenarioError(f"{where} crosses itself (its edges wind {float(turns.sum()) / (2 * math.pi):.0f} "
                                "times around); list the vertices in order around the boundary")
        return cls(v)

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """(xmin, xmax, ymin, ymax)."""
        v = self.vertices
        return float(v[:, 0].min()), float(v[:, 0].max()), float(v[:, 1].min()), float(v[:, 1].max())

    def contains(self, points: np.ndarray) -> np.ndarray:
        """Boolean mask of points (..., 2) inside or on the boundary."""
        return self.signed_distance(points) >= 0.0

    def signed_distance(self, points: np.ndarray) -> np.ndarray:
        """Signed distance (m) of points (..., 2) to the boundary: positive inside. Vectorised."""
        p = np.asarray(points, dtype=float)
        flat = p.reshape(-1, 2)
        # distance outside each supporting line; max over edges <= 0 means inside
        line = flat @ self.normals.T - self.offsets  # (N, n)
        inside = np.all(line <= 0.0, axis=1)
        v = self.vertices
        e = np.roll(v, -1, axis=0) - v
        rel = flat[:, None, :] - v[None, :, :]  # (N, n, 2)
        s = np.clip(np.einsum("pij,ij->pi", rel, e) / np.einsum("ij,ij->i", e, e), 0.0, 1.0)
        closest = v[None] + s[..., None] * e[None]
        seg = np.hypot(flat[:, 0, None] - closest[..., 0], flat[:, 1, None] - closest[..., 1]).min(axis=1)
        out = np.where(inside, -line.max(axis=1), -seg)
        return out.reshape(p.shape[:-1])

    def signed_distance_xy(self, x: float, y: float) -> float:
        """Scalar version of :meth:`signed_distance`, a few microseconds, for per-step monitoring."""
        box = self._box
        if box is not None:
            dx = max(box[0] - x, x - box[1])  # > 0 outside in x
            dy = max(box[2] - y, y - box[3])
            if dx <= 0.0 and dy <= 0.0:
                return -(dx if dx > dy else dy)
            return -math.hypot(dx if dx > 0.0 else 0.0, dy if dy > 0.0 else 0.0)
        worst = -math.inf
        for _, _, _, _, nx, ny, off, _ in self._edges_py:
            d = nx * x + ny * y - off
            if d > worst:
                worst = d
        if worst <= 0.0:
            return -worst
        best = math.inf
        for vx, vy, ex, ey, _, _, _, ee in self._edges_py:
            t = ((x - vx) * ex + (y - vy) * ey) / ee
            t = 0.0 if t < 0.0 else (1.0 if t > 1.0 else t)
            dx = x - vx - t * ex
            dy = y - vy - t * ey
            d2 = dx * dx + dy * dy
            if d2 < best:
                best = d2
        return -math.sqrt(best)


def _check_coordinates(v: np.ndarray, where: str) -> None:
    worst = float(np.max(np.abs(v))) if v.size else 0.0
    if not worst <= MAX_COORDINATE_M:  # also catches NaN
        raise ScenarioError(f"{where}: coordinates must be finite and within +-{MAX_COORDINATE_M:g} m, got {worst:g}")


def _drop_repeats(v: np.ndarray) -> np.ndarray:
    """Vertices without consecutive repeats (cyclically: a closing copy of the first vertex goes too)."""
    scale = max(float(np.max(np.abs(v))), 1.0)
    keep = [0]
    for i in range(1, len(v)):
        if np.max(np.abs(v[i] - v[keep[-1]])) > 1e-12 * scale:
            keep.append(i)
    while len(keep) > 1 and np.max(np.abs(v[keep[-1]] - v[keep[0]])) <= 1e-12 * scale:
        keep.pop()
    return v[keep]
