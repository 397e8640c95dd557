"""What the tether world needs of a station: the sizes and ranges checked on load, before anything is built.

A station file is read by shapely (free space, line of sight, visibility), by pymunk (walls, cargo, joints) and
by the planners (decomposition, reachability), and each of them can be made to hang or to return NaN by a
value the TOML reader accepts: anchor spacing of a micrometre (seventy million anchors), coordinates of 1e155
(shapely's buffers never end), five thousand vertices (the pairwise wall test), a million robots (the
observation), subnormal masses and speeds (divisions by zero). The loader calls these checks so that every
such file is a :class:`~impact_env.errors.ScenarioError` naming the field; the timing limits are the impact
scenarios' own (:mod:`impact_env.limits`). ``docs/station_format.md#limits`` lists them for users.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import shapely
from shapely.geometry import LineString

from impact_env.errors import ScenarioError
from impact_env.limits import MAX_MASS_KG, MIN_MASS_KG

MAX_ROBOTS = 32  # each robot adds an anchor one-hot to every observation
MAX_ANCHORS = 500  # the line-of-sight mask, the action space and the planners' visibility polygons grow with them
MAX_VERTICES = 500  # walls: the simplicity test, the free space, the convex decomposition
MAX_COORDINATE_M = 1e4  # a station 20 km across; the ISS is 109 m (beyond it shapely's buffers lose precision)
MIN_LENGTH_M = 1e-3  # walls, radii, goal box, anchor spacing: a millimetre (subnormal lengths divide by zero)
MIN_SPEED_MPS = 1e-4  # pulling speed and rest speed
MAX_SPEED_MPS = 100.0
MIN_FORCE_N, MAX_FORCE_N = 1e-6, 1e9
MIN_CONTROL_PERIOD_S = 1e-3


def check_range(value: float, where: str, low: float, high: float, unit: str) -> float:
    """``value`` if it lies in [low, high] (``low > 0``), else a ScenarioError naming ``where`` and the range."""
    if value <= 0:
        raise ScenarioError(f"{where} must be > 0, got {value}")
    if not low <= value <= high:
        raise ScenarioError(f"{where} must be in [{low:g}, {high:g}] {unit}, got {value:g}")
    return value


def check_coordinates(points: Sequence[tuple[float, float]], where: str) -> None:
    """Every coordinate within +-MAX_COORDINATE_M."""
    for i, p in enumerate(points):
        if not (abs(p[0]) <= MAX_COORDINATE_M and abs(p[1]) <= MAX_COORDINATE_M):
            raise ScenarioError(f"{where}[{i}] = {list(p)}: coordinates must be within +-{MAX_COORDINATE_M:g} m")


def anchors_of_spacing(lengths: Sequence[float], spacing_m: float) -> int:
    """How many anchors the spacing rule puts on walls of these lengths (before building any of them)."""
    total = 0
    for length in lengths:
        parts = length / spacing_m + 1e-9
        if not parts < MAX_ANCHORS + 1:
            return MAX_ANCHORS + 1
        total += max(1, math.floor(parts))
    return total


def wall_crossing(pts: Sequence[tuple[float, float]], where: str) -> None:
    """Raise a ScenarioError naming two walls that cross or overlap, if any (the polygon must be simple).

    GEOS answers whether the ring is simple in O(n log n); only a ring that is not is searched for the pair
    to name, with a spatial index over the walls, so a 500-vertex station loads in milliseconds.
    """
    n = len(pts)
    ring = shapely.LinearRing(pts)
    if shapely.is_simple(ring):
        return
    lines = [LineString([pts[i], pts[(i + 1) % n]]) for i in range(n)]
    tree = shapely.STRtree(lines)
    for i in range(n):
        for j in sorted(int(k) for k in tree.query(lines[i]) if k > i):
            inter = lines[i].intersection(lines[j])
            if inter.is_empty:
                continue
            adjacent = j == i + 1 or (i == 0 and j == n - 1)
            if adjacent and inter.geom_type == "Point":
                continue
            at = inter.representative_point()
            what = "overlap" if adjacent or inter.geom_type != "Point" else "cross"
            raise ScenarioError(f"{where} is not simple: walls {i} ({list(pts[i])} -> {list(pts[(i + 1) % n])}) and "
                                f"{j} ({list(pts[j])} -> {list(pts[(j + 1) % n])}) {what} at "
                                f"[{at.x:.6g}, {at.y:.6g}]; the station must be a simple polygon without holes")
    raise ScenarioError(f"{where} is not simple (two walls touch); the station must be a simple polygon without holes")


def check_mass(mass_kg: float, where: str) -> float:
    return check_range(mass_kg, where, MIN_MASS_KG, MAX_MASS_KG, "kg")


def polygon_area2(pts: Sequence[tuple[float, float]]) -> float:
    """Twice the signed area (positive counter-clockwise)."""
    xs, ys = np.array([p[0] for p in pts]), np.array([p[1] for p in pts])
    return float(np.sum(xs * np.roll(ys, -1) - np.roll(xs, -1) * ys))
