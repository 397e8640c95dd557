"""Bezier curve utilities (paper Eq. 8): evaluation, derivatives, bounding boxes, splitting, elevation.

Control points are arrays of shape (degree + 1, dim); the phase s runs over [0, 1].
"""

from __future__ import annotations

from functools import lru_cache
from math import comb

import numpy as np


@lru_cache(maxsize=32)
def _binomials(degree: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(b, d - b, C(d, b)) for b = 0..d, read-only (the control loop evaluates curves every step)."""
    b = np.arange(degree + 1)
    out = (b, degree - b, np.array([comb(degree, k) for k in b], dtype=float))
    for a in out:
        a.flags.writeable = False
    return out


def bernstein(degree: int, s: np.ndarray | float) -> np.ndarray:
    """Bernstein basis values, shape (len(s), degree + 1): C(d, b) (1 - s)^(d - b) s^b (Eq. 8)."""
    s = np.asarray(s, dtype=float)
    s = s.reshape(-1, 1) if s.ndim <= 1 else s[:, None]  # np.atleast_1d(s)[:, None], with less dispatch
    b, rest, coef = _binomials(degree)
    return coef * (1.0 - s) ** rest * s ** b


def evaluate(control_points: np.ndarray, s: np.ndarray | float) -> np.ndarray:
    """Points of the curve at phases ``s``: shape (len(s), dim)."""
    cp = np.asarray(control_points, dtype=float)
    return bernstein(len(cp) - 1, s) @ cp


def derivative(control_points: np.ndarray) -> np.ndarray:
    """Control points of dr/ds, a Bezier curve of one degree less: d (r^(b+1) - r^(b))."""
    cp = np.asarray(control_points, dtype=float)
    d = len(cp) - 1
    if d == 0:
        return np.zeros_like(cp)
    return d * (cp[1:] - cp[:-1])  # np.diff(cp, axis=0), the same numbers


def bounding_box(control_points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) corners of the box that contains the curve (convex hull property)."""
    cp = np.asarray(control_points, dtype=float)
    return cp.min(axis=0), cp.max(axis=0)


def split(control_points: np.ndarray, s: float) -> tuple[np.ndarray, np.ndarray]:
    """De Casteljau: the curve on [0, s] and on [s, 1], each as a Bezier of the same degree."""
    pts = np.asarray(control_points, dtype=float)
    left, right = [pts[0]], [pts[-1]]
    while len(pts) > 1:
        pts = (1.0 - s) * pts[:-1] + s * pts[1:]
        left.append(pts[0])
        right.append(pts[-1])
    return np.array(left), np.array(right[::-1])


def elevate(control_points: np.ndarray) -> np.ndarray:
    """The same curve as a Bezier of one degree more."""
    cp = np.asarray(control_points, dtype=float)
    d = len(cp) - 1
    out = np.empty((d + 2,) + cp.shape[1:])
    out[0], out[-1] = cp[0], cp[-1]
    for i in range(1, d + 1):
        a = i / (d + 1)
        out[i] = a * cp[i - 1] + (1.0 - a) * cp[i]
    return out
