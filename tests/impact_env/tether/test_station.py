"""Station files: the shipped maps, the anchor rule, geometry helpers and every validation message."""

from __future__ import annotations

import math

import numpy as np
import pytest
from shapely.geometry import LineString, Point, Polygon

from impact_env.errors import ScenarioError
from impact_env.tether.station import load_station, station_from_dict, station_names
from tests.helpers import DELETE, modified
from tests.station_helpers import L_POLYGON, make_station, station_dict

REFERENCE = {  # the reference benchmark maps: counter-clockwise polygon, start, goal
    "L": ([(0, 0), (5, 0), (5, 10), (20, 10), (20, 15), (0, 15)], (2.5, 1.5), (18.5, 12.5)),
    "T": ([(0, 10), (10, 10), (10, 0), (15, 0), (15, 10), (25, 10), (25, 15), (0, 15)], (12.5, 1.5), (1.5, 12.5)),
    "alcove": ([(0, 0), (30, 0), (30, 6), (26, 6), (26, 8), (22, 8), (22, 6), (14, 6), (14, 12), (8, 12), (8, 6),
                (0, 6)], (1.5, 3.0), (11.0, 10.5)),
}


def _signed_area(polygon) -> float:
    p = np.asarray(polygon, dtype=float)
    return 0.5 * float(np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1]))


def _rule_count(polygon, spacing: float) -> int:
    n = len(polygon)
    return sum(max(1, math.floor(math.dist(polygon[i], polygon[(i + 1) % n]) / spacing + 1e-9)) for i in range(n))


def test_shipped_stations():
    assert set(station_names()) >= {"L", "T", "alcove", "iss_chain", "dead_end"}
    for name in station_names():
        s = load_station(name)
        assert s.name == name and _signed_area(s.polygon) > 0, name
        poly = s.shapely_polygon
        for a in s.anchors:  # on its own wall
            (x0, y0), (x1, y1) = s.walls[a.wall]
            assert LineString([(x0, y0), (x1, y1)]).distance(Point(a.position_m)) < 1e-12
            assert poly.exterior.distance(Point(a.position_m)) < 1e-12
        assert s.cargo_inside(s.cargo.start_m)
        assert s.task == s.hold_task == "F[0,570] G[0,30] (in(cargo, goal) & in(drift, rest))"
        assert s.reach_task == "F[0,600] in(cargo, goal)" and s.formula.horizon_s == 600.0


@pytest.mark.parametrize("name", sorted(REFERENCE))
def test_reference_maps_and_thesis_defaults(name):
    polygon, start, goal = REFERENCE[name]
    s = load_station(name)
    assert s.polygon == tuple((float(x), float(y)) for x, y in polygon)
    assert s.cargo.start_m == start and s.goal_center_m == goal
    assert s.cargo.radius_m == 0.3 and s.stop_radius_m == 0.6 and s.pull_speed_mps == 0.1
    assert s.goal_box == (goal[0] - 0.5, goal[0] + 0.5, goal[1] - 0.5, goal[1] + 0.5)
    assert s.n_anchors == _rule_count(polygon, 2.5)


def test_l_anchors_follow_the_spacing_rule():
    s = load_station("L")
    # walls 5, 10, 15, 5, 20, 15 m: 2, 4, 6, 2, 8, 6 parts, one anchor in the middle of each
    assert [sum(a.wall == i for a in s.anchors) for i in range(6)] == [2, 4, 6, 2, 8, 6]
    np.testing.assert_allclose(s.anchor_positions[:2], [[1.25, 0.0], [3.75, 0.0]])
    np.testing.assert_allclose(s.anchor_positions[[a.wall == 4 for a in s.anchors]][:, 0],
                               [18.75, 16.25, 13.75, 11.25, 8.75, 6.25, 3.75, 1.25])


def test_dead_end_arm_has_anchors_only_at_its_end():
    s = load_station("dead_end")
    arm = [a for a in s.anchors if a.position_m[1] > 8.0]
    assert [a.position_m for a in arm] == [(9.0, 16.0)]
    visible = {a.position_m for a, v in zip(s.anchors, s.line_of_sight(s.cargo.start_m)) if v}
    assert visible == {(9.0, 16.0), (7.5, 0.0), (10.5, 0.0)}  # the end wall and two hall anchors below the opening


def test_clockwise_file_is_the_same_station():
    ccw = make_station()
    cw = make_station([L_POLYGON[0]] + L_POLYGON[:0:-1])
    assert cw.polygon == ccw.polygon and cw.anchors == ccw.anchors


def test_wall_indices_refer_to_the_file_order():
    # the bottom wall is wall 0 as written in both orientations; anchors only there
    ccw = make_station(anchors={"spacing_m": 2.5, "walls": [0]})
    cw_polygon = [L_POLYGON[1], L_POLYGON[0]] + L_POLYGON[:1:-1]  # starts with the bottom wall, clockwise
    cw = make_station(cw_polygon, anchors={"spacing_m": 2.5, "walls": [0]})
    for s in (ccw, cw):
        assert sorted(a.position_m for a in s.anchors) == [(1.25, 0.0), (3.75, 0.0)]


def test_listed_anchors_are_projected_onto_their_wall_and_merge_with_the_rule():
    s = make_station(anchors={"spacing_m": 10.0, "walls": [0], "points": [[20.0 + 4e-7, 12.0], [1.0, 15.0]]})
    assert [a.position_m for a in s.anchors] == [(2.5, 0.0), (20.0, 12.0), (1.0, 15.0)]
    assert [a.wall for a in s.anchors] == [0, 3, 4] and [a.index for a in s.anchors] == [0, 1, 2]


def test_free_space_area_closed_form():
    """Erosion of the L by the 0.3 m disc: two rectangles, plus the square at the notch minus its quarter disc."""
    s = load_station("L")
    r = 0.3
    rectangles = (5 - 2 * r) * (15 - 2 * r) + (20 - 2 * r) * (5 - 2 * r) - (5 - 2 * r) ** 2
    assert s.free_space().area == pytest.approx(rectangles + r * r * (1 - math.pi / 4), abs=2e-4)
    assert s.free_space(quad_segs=64).area == pytest.approx(rectangles + r * r * (1 - math.pi / 4), abs=2e-5)
    assert s.shapely_polygon.covers(s.free_space())


def test_line_of_sight_from_the_l_start():
    """From (2.5, 1.5) a tether reaches what stays in the shaft (x <= 5) below y = 10: computed by hand."""
    s = load_station("L")
    visible = {a.position_m for a, v in zip(s.anchors, s.line_of_sight((2.5, 1.5))) if v}
    expected = {(1.25, 0.0), (3.75, 0.0)} | {(5.0, y) for y in (1.25, 3.75, 6.25, 8.75)} \
        | {(0.0, y) for y in (1.25, 3.75, 6.25, 8.75, 11.25, 13.75)} | {(1.25, 15.0), (3.75, 15.0), (6.25, 15.0)}
    assert visible == expected


def test_line_of_sight_grazing_a_notch_is_visible():
    # from (3, 2) the segment to (4.5, 5) passes exactly through the notch (4, 4): touching is not blocking
    s = make_station([[0, 0], [6, 0], [6, 5], [4, 5], [4, 4], [0, 4]], start=(3, 2), goal=(3, 2),
                     anchors={"points": [[4.5, 5.0]]})
    assert s.line_of_sight((3.0, 2.0)).tolist() == [True]
    assert s.line_of_sight((3.0 + 1e-6, 2.0)).tolist() == [True]  # right of the notch, inside the column
    assert s.line_of_sight((3.0 - 1e-6, 2.0)).tolist() == [False]  # left of it: outside, above the lower room
    np.testing.assert_array_equal(s.notches, [[4.0, 4.0]])


def test_line_of_sight_past_the_notch():
    """The segment to (7.5, 15) passes the notch (5, 10) above it from x = 2.4 and below it from x = 2.6."""
    s = make_station(anchors={"points": [[7.5, 15.0]]})
    assert s.line_of_sight((2.4, 5.0)).tolist() == [True]
    assert s.line_of_sight((2.6, 5.0)).tolist() == [False]
    assert s.line_of_sight((2.6, 5.0), anchors=[]).shape == (0,)


BAD = [
    ("name", DELETE, "name is required"),
    ("colour", "red", "colour: unknown key"),
    ("station.polygon", [[0, 0], [1, 0]], "at least 3 vertices"),
    ("station.polygon", [[0, 0], [5, 0], [5, 5], [0, 5], [0, 0]], "the last vertex repeats the first"),
    ("station.polygon", [[0, 0], [5, 0], [5, 5], [5, 0], [0, 5]], "station.polygon[3] = [5.0, 0.0] repeats vertex 1"),
    ("station.polygon", [[0, 0], [5, 5], [5, 0], [0, 5]], "walls 0 ([0.0, 0.0] -> [5.0, 5.0]) and 2"),
    ("station.polygon", [[0, 0], [4, 0], [4, 4], [2, 0], [0, 4]], "not simple"),
    ("station.polygon", [[0, 0], [4, 0], [8, 0]], "zero area"),
    ("station.polygon", [[0, 0], [4, "x"], [0, 4]], "station.polygon[1][1] must be a finite number"),
    ("station.extra", 1, "station.extra: unknown key"),
    ("cargo.radius_m", -0.2, "cargo.radius_m must be > 0, got -0.2"),
    ("cargo.start_m", [0.1, 1.5], "puts the cargo disc (radius 0.3 m) partly outside the station"),
    ("cargo.start_m", [10.0, 5.0], "its centre is outside the station"),
    ("goal.center_m", [18.5, 14.8], "is not inside the station polygon"),
    ("goal.box", [1, 2, 1, 2], "exactly one of 'box"),
    ("goal.half_size_m", DELETE, "goal.half_size_m is required with goal.center_m"),
    ("robots.count", 0, "robots.count must be >= 1"),
    ("robots.max_active", 4, "robots.max_active must be in 1..robots.count = 3, got 4"),
    ("robots.pull_speed_mps", 0.0, "robots.pull_speed_mps must be > 0"),
    ("robots.switch_time_s", -1.0, "robots.switch_time_s must be >= 0"),
    ("robots.stop_radius_m", 0.2, "robots.stop_radius_m = 0.2 must be >= cargo.radius_m = 0.3"),
    ("robots.speed", 1.0, "robots.speed: unknown key"),
    ("anchors", {}, "anchors needs 'spacing_m'"),
    ("anchors", {"spacing_m": -1.0}, "anchors.spacing_m must be > 0"),
    ("anchors", {"walls": [0]}, "it needs anchors.spacing_m"),
    ("anchors", {"spacing_m": 2.5, "walls": [6]}, "anchors.walls[0] = 6 is not a wall; walls are 0..5"),
    ("anchors", {"spacing_m": 2.5, "walls": [1, 1]}, "anchors.walls[1] = 1 is listed twice"),
    ("anchors", {"points": [[2.0, 2.0]]}, "anchors.points[0] = [2.0, 2.0] is not on a wall"),
    ("anchors", {"spacing_m": 2.5, "points": [[1.25, 0.0]]}, "two anchors at [1.25, 0.0]"),
    ("restitution", 1.5, "restitution must be in [0, 1]"),
    ("substeps", 1, "substeps = 1 is too few"),
    ("task", "F[0,600] in(robot, goal)", "task names body 'robot'"),
    ("task", "F[0,600] in(cargo, hatch)", "task names region 'hatch'"),
    ("task", "F[0,700] in(cargo, goal)", "task horizon 700.0 s exceeds tf_s = 600.0 s"),
    ("task", "in(cargo, goal)", "no temporal operator"),
    ("task", "F[0,600] in(cargo goal", "task:"),
]


@pytest.mark.parametrize("path,value,message", BAD, ids=[f"{p}:{m[:30]}" for p, _, m in BAD])
def test_bad_fields_raise_scenario_error_naming_them(path, value, message):
    with pytest.raises(ScenarioError) as info:
        station_from_dict(modified(station_dict(), path, value), source="bad.toml")
    assert message in str(info.value) and str(info.value).startswith("bad.toml: ")


def test_narrow_passage_gives_a_free_space_in_pieces():
    # two rooms joined by a 0.5 m slot: the 0.3 m cargo cannot pass, the free space has two parts
    polygon = [[0, 0], [4, 0], [4, 1.75], [6, 1.75], [6, 0], [10, 0], [10, 4], [6, 4], [6, 2.25], [4, 2.25], [4, 4],
               [0, 4]]
    s = make_station(polygon, start=(2, 2), goal=(8, 2))
    assert s.free_space().geom_type == "MultiPolygon" and len(s.free_space().geoms) == 2


# ------------------------------------------------------------------------------------- property tests


def histogram_polygons():
    """Orthogonal 'histogram' polygons: a flat bottom and 2-6 columns of random widths and heights (m). A
    hypothesis strategy, built when a test draws from it (hypothesis is not imported to collect the suite)."""
    from hypothesis import strategies as st

    @st.composite
    def polygons(draw):
        widths = draw(st.lists(st.integers(2, 6), min_size=2, max_size=6))
        heights = draw(st.lists(st.integers(2, 8), min_size=len(widths), max_size=len(widths)))
        pts, x = [(0.0, 0.0), (float(sum(widths)), 0.0)], float(sum(widths))
        for w, h in zip(reversed(widths), reversed(heights)):
            pts.append((x, float(h)))
            x -= w
            pts.append((x, float(h)))
        # equal neighbouring heights repeat a vertex: keep one (the straight wall then has a collinear vertex)
        unique = [p for i, p in enumerate(pts) if p != pts[i - 1]]
        return [list(p) for p in unique]

    return polygons()


def test_property_any_orthogonal_station():
    from hypothesis import given, settings
    from hypothesis import strategies as st

    @settings(max_examples=40, deadline=None)
    @given(polygon=histogram_polygons(), spacing=st.sampled_from([1.0, 2.5, 5.0]), reverse=st.booleans())
    def check(polygon, spacing, reverse):
        poly = Polygon(polygon)
        free = poly.buffer(-0.3)
        start = free.representative_point()
        goal_box = Point(start.x, start.y).buffer(0.5, cap_style="square")
        if not poly.covers(goal_box):  # keep the goal inside; the start is then also the goal centre
            return
        written = polygon if not reverse else [polygon[0]] + polygon[:0:-1]
        s = make_station(written, start=(start.x, start.y), goal=(start.x, start.y), anchors={"spacing_m": spacing})
        assert _signed_area(s.polygon) > 0 and abs(_signed_area(s.polygon)) == pytest.approx(poly.area)
        assert s.n_anchors == _rule_count(s.polygon, spacing)
        for a in s.anchors:
            assert poly.exterior.distance(Point(a.position_m)) < 1e-9
        # line of sight agrees with dense sampling of the segment (visible -> every sample inside the polygon;
        # hidden -> the segment leaves the polygon by more than rounding)
        mask = s.line_of_sight((start.x, start.y))
        grown = poly.buffer(1e-6)
        for a, visible in zip(s.anchors, mask):
            seg = LineString([(start.x, start.y), a.position_m])
            samples = [seg.interpolate(t, normalized=True) for t in np.linspace(0.0, 1.0, 101)]
            if visible:
                assert all(poly.buffer(1e-9).covers(q) for q in samples)
            elif not any(seg.distance(Point(v)) < 1e-6 for v in s.polygon):
                # hidden: the segment leaves the polygon by more than rounding, unless it grazes a corner, where
                # either answer is right (the tether would touch the wall there)
                assert not grown.covers(seg)

    check()
