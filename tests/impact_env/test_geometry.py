"""Signed distance of convex polygons against shapely, including the box fast path."""

from __future__ import annotations

import numpy as np
import pytest
import shapely

from impact_env.errors import ScenarioError
from impact_env.geometry import ConvexPolygon


def _reference(poly: ConvexPolygon, p: np.ndarray) -> float:
    shape = shapely.Polygon(poly.vertices)
    d = shape.exterior.distance(shapely.Point(p))
    return d if shape.covers(shapely.Point(p)) else -d


@pytest.mark.parametrize("poly", [
    ConvexPolygon.from_box(0.25, 1.75, 7.25, 8.75),
    ConvexPolygon.from_vertices([[0, 0], [2, 0], [3, 1.5], [1, 3], [-0.5, 1]]),
    ConvexPolygon.from_vertices([[0, 0], [0, 1], [1, 0]]),  # clockwise input gets reordered
])
def test_signed_distance_matches_shapely(poly):
    rng = np.random.default_rng(0)
    pts = rng.uniform(-2, 10, (400, 2))
    expected = np.array([_reference(poly, p) for p in pts])
    np.testing.assert_allclose(poly.signed_distance(pts), expected, atol=1e-12)
    np.testing.assert_allclose([poly.signed_distance_xy(*p) for p in pts], expected, atol=1e-12)


def test_box_and_general_paths_agree():
    box = ConvexPolygon.from_box(-1, 2, 0, 1)
    general = ConvexPolygon.from_vertices([[-1, 0], [2, 0], [2, 1], [-1, 1], ])
    object.__setattr__(general, "_box", None)
    rng = np.random.default_rng(1)
    for p in rng.uniform(-3, 4, (200, 2)):
        assert box.signed_distance_xy(*p) == pytest.approx(general.signed_distance_xy(*p), abs=1e-12)


def test_invalid_polygons():
    with pytest.raises(ScenarioError, match="not convex"):
        ConvexPolygon.from_vertices([[0, 0], [2, 0], [1, 0.5], [2, 2], [0, 2]])
    with pytest.raises(ScenarioError, match="zero area"):
        ConvexPolygon.from_vertices([[0, 0], [1, 1], [2, 2]])
    with pytest.raises(ScenarioError, match="at least 3"):
        ConvexPolygon.from_vertices([[0, 0], [1, 1]])
