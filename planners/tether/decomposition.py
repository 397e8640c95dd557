"""The thesis's convex decomposition of the station map: MP3 (Sec. 4.1, Algorithms 1 and 2).

MP3 (Fernandez, Toth, Canovas and Pelegrin, the thesis's reference [10]) cuts a simple polygon into convex
pieces by diagonals. :func:`mp3_step` (Algorithm 1) takes the polygon as a clockwise vertex list and a start
index and extracts one convex piece: forward growth under a three-angle convexity test, ``Check_L``
(Algorithm 2, :func:`check_l`) cutting the piece where a notch lies in it, backward growth, and acceptance
when the piece's first or last vertex is a notch. :func:`mp3_decompose` iterates it on the remainder until
the remainder is convex. Where the text is garbled or leaves a reading open (the acceptance test, Algorithm
2's cut, a start that gives no piece), the choices made: ``docs/planner_design.md#convex-decomposition``.

The result is verified: the pieces must tile the polygon (areas add up, no overlap) and be convex, else
:class:`DecompositionError` (it would be a bug, and the test sweep over random orthogonal polygons looks for it).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import shapely
from shapely.geometry import Polygon

from planners.tether.errors import DecompositionError

Point = tuple[float, float]


def _area(pts: Sequence[Point]) -> float:
    """Unsigned shoelace area."""
    x = np.array([p[0] for p in pts])
    y = np.array([p[1] for p in pts])
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y)))


def _cross(o: Point, a: Point, b: Point) -> float:
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])


class _Geometry:
    """Angle tests with a tolerance scaled to the polygon's size (clockwise convention of the thesis)."""

    def __init__(self, pts: Sequence[Point]) -> None:
        xs, ys = zip(*pts)
        scale = max(max(xs) - min(xs), max(ys) - min(ys), 1e-12)
        self.eps = 1e-10 * scale * scale

    def convex(self, a: Point, b: Point, c: Point) -> bool:
        """``ang(a, b, c) <= 180 deg`` for a clockwise walk a -> b -> c: a right turn or straight on."""
        return _cross(a, b, c) <= self.eps

    def notch(self, a: Point, b: Point, c: Point) -> bool:
        """``b`` is a notch (internal angle > 180 deg) of a clockwise polygon with neighbours a, c."""
        return _cross(a, b, c) > self.eps

    def inside(self, p: Point, piece: Sequence[Point]) -> bool:
        """``p`` in the closed convex clockwise polygon ``piece`` (on its boundary counts)."""
        k = len(piece)
        return all(_cross(piece[i], piece[(i + 1) % k], p) <= self.eps for i in range(k))


def to_clockwise(polygon: Sequence[Sequence[float]]) -> list[Point]:
    """The vertex list clockwise (the thesis's orientation), keeping the first vertex."""
    pts = [(float(x), float(y)) for x, y in polygon]
    if Polygon(pts).exterior.is_ccw:
        pts = [pts[0]] + pts[:0:-1]
    return pts


def notches(polygon: Sequence[Point]) -> list[int]:
    """Indices of the notches (reflex vertices) of a clockwise polygon."""
    g = _Geometry(polygon)
    n = len(polygon)
    return [i for i in range(n) if g.notch(polygon[i - 1], polygon[i], polygon[(i + 1) % n])]


def is_convex(polygon: Sequence[Point]) -> bool:
    return not notches(polygon)


def check_l(P: Sequence[Point], L: list[int], backward: bool = False) -> bool:
    """Algorithm 2 (Check_L) on ``L`` (indices into ``P``, in order); cuts ``L`` in place, True if it changed.

    The notches tested are those of ``P \\ L`` (the remainder keeps ``l_1`` and ``l_k``, which are on ``L``'s
    closing diagonal and not tested). First the cheap test against ``R``, the bounding box of ``L``, then the
    test against ``L`` itself (closed: a notch on the diagonal would make it touch the remainder).
    """
    if len(L) < 3:
        return False
    g = _Geometry(P)
    inner = set(L[1:-1])
    rest = [i for i in range(len(P)) if i not in inner]  # P \ L, in order
    m = len(rest)
    piece = [P[i] for i in L]
    xs, ys = zip(*piece)
    x0, x1, y0, y1 = min(xs) - 1e-9, max(xs) + 1e-9, min(ys) - 1e-9, max(ys) + 1e-9
    for j, i in enumerate(rest):
        if i in (L[0], L[-1]):
            continue
        v = P[i]
        if not g.notch(P[rest[j - 1]], v, P[rest[(j + 1) % m]]):
            continue
        if not (x0 <= v[0] <= x1 and y0 <= v[1] <= y1):  # not in R
            continue
        if not g.inside(v, piece):
            continue
        # cut: the line through the fixed end and the notch; drop the growing end and the vertices on its side
        fixed, grow = (L[-1], L[0]) if backward else (L[0], L[-1])
        side = _cross(P[fixed], v, P[grow])
        keep = [i2 for i2 in L if i2 != grow and (i2 == fixed or _cross(P[fixed], v, P[i2]) * side <= 0.0)]
        L[:] = keep
        return True
    return False


def _grows(P: Sequence[Point], L: list[int], v: int, g: _Geometry, front: bool) -> bool:
    """The three-angle test of Sec. 4.1: adding ``v`` keeps ``L`` convex."""
    pts = [P[i] for i in L]
    q = P[v]
    if front:  # v becomes the new first vertex
        return g.convex(pts[-1], q, pts[0]) and g.convex(q, pts[0], pts[1]) and g.convex(pts[-2], pts[-1], q)
    return g.convex(q, pts[0], pts[1]) and g.convex(pts[-1], q, pts[0]) and g.convex(pts[-2], pts[-1], q)


def mp3_step(P: Sequence[Point], s: int, require_notch: bool = True) -> tuple[list[Point], list[Point], int]:
    """Algorithm 1 (MP3): one convex piece of the clockwise polygon ``P`` from start index ``s``.

    Returns ``(L, P \\ L, f)``: the piece (clockwise vertices), the remainder (clockwise) and the index in the
    remainder of ``L``'s last vertex. ``L = []`` (with the remainder ``P`` and 0) when ``P`` is convex or no piece
    is accepted from this start.
    """
    n = len(P)
    g = _Geometry(P)
    if is_convex(P):
        return [], list(P), 0
    s %= n
    L = [s, (s + 1) % n]
    i = s + 2
    while len(L) < n and _grows(P, L, i % n, g, front=False):
        L.append(i % n)
        i += 1
    while check_l(P, L):
        pass
    if len(L) >= 2:
        i = L[0] - 1
        while len(L) < n and (i % n) not in L and _grows(P, L, i % n, g, front=True):
            L.insert(0, i % n)
            i -= 1
        while check_l(P, L, backward=True):
            pass
    nset = set(notches(P))
    if len(L) > 2 and _area([P[k] for k in L]) > g.eps and (not require_notch or L[0] in nset or L[-1] in nset):
        inner = set(L[1:-1])
        rest = [k for k in range(n) if k not in inner]
        return [P[k] for k in L], [P[k] for k in rest], rest.index(L[-1])
    return [], list(P), 0


def mp3_decompose(polygon: Sequence[Sequence[float]], start: int = 0) -> list[Polygon]:
    """Convex pieces of a simple polygon by repeated MP3 steps (Sec. 4.1); counter-clockwise shapely Polygons.

    Args:
        polygon: the vertices, either orientation, each once.
        start: the first call's start index (into the clockwise list, whose first vertex is ``polygon[0]``).

    Raises:
        DecompositionError: the polygon is not simple or has fewer than 3 vertices, or (a bug) the pieces do not
            tile it.
    """
    if len(polygon) < 3:
        raise DecompositionError(f"polygon must have at least 3 vertices, got {len(polygon)}")
    whole = Polygon(polygon)
    if not whole.is_valid or whole.area <= 0:
        raise DecompositionError(f"polygon is not simple (shapely: {shapely.is_valid_reason(whole)})")
    P = to_clockwise(polygon)
    pieces: list[list[Point]] = []
    s = start
    eps = _Geometry(P).eps
    while not is_convex(P) and _area(P) > eps:
        found = None
        for require_notch in (True, False):
            for attempt in range(len(P)):
                L, rest, f = mp3_step(P, s + attempt, require_notch)
                if L:
                    found = (L, rest, f)
                    break
            if found:
                break
        if found is None:  # pragma: no cover - a non-convex polygon always has a notch-ended convex piece
            raise DecompositionError(f"MP3 found no convex piece of the remainder {P}")
        L, P, s = found
        pieces.append(L)
    if _area(P) > eps:  # the convex remainder (an empty sliver when the last cut took everything)
        pieces.append(list(P))
    out = [shapely.orient_polygons(Polygon(p)) for p in pieces]
    verify_tiling(whole, out)
    return out


def verify_tiling(whole: Polygon, pieces: Sequence[Polygon], tol: float = 1e-7) -> None:
    """Raise :class:`DecompositionError` unless the pieces are convex and tile ``whole`` exactly."""
    scale = max(whole.area, 1e-12)
    total = sum(p.area for p in pieces)
    union = shapely.union_all(pieces)
    missing = whole.difference(union).area
    for k, p in enumerate(pieces):
        if not p.is_valid or p.area <= 0:
            raise DecompositionError(f"piece {k} is degenerate: {list(p.exterior.coords)}")
        if p.convex_hull.area - p.area > tol * scale:
            raise DecompositionError(f"piece {k} is not convex: {list(p.exterior.coords)}")
    if abs(total - whole.area) > tol * scale or missing > tol * scale:
        raise DecompositionError(f"pieces do not tile the polygon: area {whole.area:.9g} m^2, pieces add up to "
                                 f"{total:.9g} m^2, {missing:.3g} m^2 not covered")


def piece_adjacency(pieces: Sequence[Polygon], tol: float = 1e-9) -> list[tuple[int, int, tuple[Point, Point]]]:
    """Pairs of pieces that share a stretch of border (a diagonal of the decomposition), with that stretch."""
    out = []
    for i in range(len(pieces)):
        for j in range(i + 1, len(pieces)):
            shared = pieces[i].boundary.intersection(pieces[j].boundary)
            if shared.is_empty or shared.length <= tol:
                continue
            merged = shapely.line_merge(shared) if shared.geom_type != "LineString" else shared
            if merged.geom_type != "LineString":
                merged = max(shapely.get_parts(merged), key=lambda part: part.length)
            coords = np.asarray(merged.coords)
            out.append((i, j, (tuple(coords[0]), tuple(coords[-1]))))
    return out
