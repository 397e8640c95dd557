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

import numpy as np

from impact_env.errors import ScenarioError


@dataclass(frozen=True)
class ConvexPolygon:
    """A convex polygon given by its vertices in counter-clockwise order, metres.

    Build one with :meth:`from_box` or :meth:`from_vertices` (which validates and orders the vertices).
    """

    vertices: np.ndarray  # (n, 2), counter-clockwise, no repeated closing vertex
    normals: np.ndarray = field(init=False, repr=False)  # (n, 2) outward unit normals of edges i -> i+1
    offsets: np.ndarray = field(init=False, repr=False)  # (n,) so that normals @ x <= offsets inside

    def __post_init__(self) -> None:
        v = np.asarray(self.vertices, dtype=float)
        edges = np.roll(v, -1, axis=0) - v
        lengths = np.hypot(edges[:, 0], edges[:, 1])
        normals = np.stack([edges[:, 1], -edges[:, 0]], axis=1) / lengths[:, None]
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "normals", normals)
        object.__setattr__(self, "offsets", np.einsum("ij,ij->i", normals, v))
        # axis-aligned boxes (most regions) get a closed-form scalar path
        box = None
        if len(v) == 4:
            xs, ys = sorted(set(np.round(v[:, 0], 15))), sorted(set(np.round(v[:, 1], 15)))
            if len(xs) == 2 and len(ys) == 2:
                box = (float(xs[0]), float(xs[1]), float(ys[0]), float(ys[1]))
        object.__setattr__(self, "_box", box)
        # plain-float copies for the scalar fast path used once per control step
        object.__setattr__(self, "_edges_py", [
            (float(v[i, 0]), float(v[i, 1]), float(edges[i, 0]), float(edges[i, 1]),
             float(normals[i, 0]), float(normals[i, 1]), float(self.offsets[i]), float(lengths[i]) ** 2)
            for i in range(len(v))
        ])

    @classmethod
    def from_box(cls, xmin: float, xmax: float, ymin: float, ymax: float) -> ConvexPolygon:
        """Axis-aligned box [xmin, xmax] x [ymin, ymax]."""
        if not (xmin < xmax and ymin < ymax):
            raise ScenarioError(f"box must have xmin < xmax and ymin < ymax, got [{xmin}, {xmax}] x [{ymin}, {ymax}]")
        return cls(np.array([[xmin, ymin], [xmax, ymin], [xmax, ymax], [xmin, ymax]], dtype=float))

    @classmethod
    def from_vertices(cls, vertices: np.ndarray | list, where: str = "polygon") -> ConvexPolygon:
        """Validate a vertex list (either orientation) and return the counter-clockwise polygon."""
        v = np.asarray(vertices, dtype=float)
        if v.ndim != 2 or v.shape[1] != 2 or len(v) < 3:
            raise ScenarioError(f"{where} needs at least 3 vertices [x, y], got shape {v.shape}")
        if not np.all(np.isfinite(v)):
            raise ScenarioError(f"{where} has non-finite coordinates")
        area2 = float(np.sum(v[:, 0] * np.roll(v[:, 1], -1) - np.roll(v[:, 0], -1) * v[:, 1]))
        if abs(area2) < 1e-12:
            raise ScenarioError(f"{where} has zero area")
        if area2 < 0:
            v = v[::-1].copy()
        edges = np.roll(v, -1, axis=0) - v
        cross = edges[:, 0] * np.roll(edges[:, 1], -1) - edges[:, 1] * np.roll(edges[:, 0], -1)
        if np.any(cross < -1e-12):
            raise ScenarioError(f"{where} is not convex; split it into convex pieces")
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
