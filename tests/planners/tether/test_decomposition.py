"""The thesis's map pipeline: MP3 decomposition (Sec. 4.1), polygon extension (Sec. 4.2), region graph and
hybrid automaton (Sec. 4.3)."""

from __future__ import annotations

import numpy as np
import pytest
import shapely
from shapely.geometry import Polygon

from impact_env.tether.station import load_station, station_names
from planners.tether.automaton import build_automaton, build_thesis_map, half_planes
from planners.tether.decomposition import (
    check_l,
    is_convex,
    mp3_decompose,
    mp3_step,
    notches,
    to_clockwise,
    verify_tiling,
)
from planners.tether.errors import DecompositionError
from planners.tether.extension import extend_into, extend_regions
from planners.tether.random_maps import orthogonal_polygon
from tests.station_helpers import make_station

# the thesis's L map with the vertex (5, 15) its Fig. 9-10 regions need (a straight angle on the top wall)
L_THESIS = [(0, 0), (5, 0), (5, 10), (20, 10), (20, 15), (5, 15), (0, 15)]


def _boxes(pieces):
    return sorted(tuple(round(v, 9) for v in p.bounds) for p in pieces)


def _assert_tiles(polygon, pieces):
    whole = Polygon(polygon)
    assert sum(p.area for p in pieces) == pytest.approx(whole.area, rel=1e-9)
    assert whole.symmetric_difference(shapely.union_all(pieces)).area < 1e-9 * whole.area
    for i, p in enumerate(pieces):
        assert p.convex_hull.area - p.area < 1e-9 * whole.area
        for q in pieces[i + 1:]:
            assert p.intersection(q).area < 1e-9 * whole.area


def test_mp3_reproduces_the_thesis_regions_on_the_l_map():
    pieces = mp3_decompose(L_THESIS, start=0)
    # the shaft x in (0, 5), y in (0, 15) of Eq. 6 and the arm x in (5, 20), y in (10, 15)
    assert _boxes(pieces) == [(0, 0, 5, 15), (5, 10, 20, 15)]
    _assert_tiles(L_THESIS, pieces)


@pytest.mark.parametrize("start", range(7))
def test_mp3_tiles_the_l_map_from_every_start(start):
    pieces = mp3_decompose(L_THESIS, start=start)
    assert len(pieces) == 2  # one notch: one diagonal
    _assert_tiles(L_THESIS, pieces)


def test_convex_polygon_is_its_own_piece_and_mp3_step_returns_empty():
    square = [(0, 0), (4, 0), (4, 4), (0, 4)]
    assert is_convex(to_clockwise(square))
    L, rest, f = mp3_step(to_clockwise(square), 0)
    assert L == [] and len(rest) == 4 and f == 0
    assert _boxes(mp3_decompose(square)) == [(0, 0, 4, 4)]


def test_notches_and_clockwise_orientation():
    cw = to_clockwise(L_THESIS)
    assert cw[0] == (0.0, 0.0) and not Polygon(cw).exterior.is_ccw
    assert [cw[i] for i in notches(cw)] == [(5.0, 10.0)]


def test_check_l_cuts_a_piece_that_holds_a_notch():
    # a U: grown from the bottom-left corner along the bottom, a piece spanning the U's mouth holds notches
    u = to_clockwise([(0, 0), (9, 0), (9, 6), (6, 6), (6, 2), (3, 2), (3, 6), (0, 6)])
    idx = {p: i for i, p in enumerate(u)}
    L = [idx[(9.0, 6.0)], idx[(9.0, 0.0)], idx[(0.0, 0.0)], idx[(0.0, 6.0)]]  # clockwise, holds (3,2), (6,2)
    assert check_l(u, L)
    while check_l(u, L):  # Algorithm 1 repeats Check_L until L is unchanged
        pass
    # here MP1's cut leaves only the right wall: no convex piece with this start (the caller tries another)
    assert [u[i] for i in L] == [(9.0, 6.0), (9.0, 0.0)]
    # from the start (6, 6): the right column, grown backward to the notch (6, 2), which is its first vertex
    piece, rest, f = mp3_step(u, idx[(6.0, 6.0)])
    assert piece == [(6.0, 2.0), (6.0, 6.0), (9.0, 6.0), (9.0, 0.0)]
    assert rest == [(0.0, 0.0), (0.0, 6.0), (3.0, 6.0), (3.0, 2.0), (6.0, 2.0), (9.0, 0.0)] and rest[f] == piece[-1]


def test_the_u_shape_decomposes_into_three_pieces():
    u = [(0, 0), (9, 0), (9, 6), (6, 6), (6, 2), (3, 2), (3, 6), (0, 6)]
    pieces = mp3_decompose(u)
    _assert_tiles(u, pieces)
    assert len(pieces) == 3


@pytest.mark.parametrize("seed", range(12))
def test_mp3_tiles_random_orthogonal_polygons(seed):
    rng = np.random.default_rng(seed)
    polygon, _ = orthogonal_polygon(rng, notches=2 + seed % 19 if seed < 6 else 2 + (7 * seed) % 19)
    for start in (0, 3):
        pieces = mp3_decompose(polygon, start=start)
        _assert_tiles(polygon, pieces)
        # a decomposition by diagonals needs at most (notches + 1) pieces
        assert len(pieces) <= len(notches(to_clockwise(polygon))) + 1


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(100, 160))
def test_mp3_tiles_many_random_orthogonal_polygons(seed):
    polygon, _ = orthogonal_polygon(np.random.default_rng(seed), notches=2 + seed % 19)
    pieces = mp3_decompose(polygon, start=seed)
    _assert_tiles(polygon, pieces)


def test_mp3_rejects_bad_polygons_with_a_typed_error():
    with pytest.raises(DecompositionError, match="at least 3 vertices"):
        mp3_decompose([(0, 0), (1, 1)])
    with pytest.raises(DecompositionError, match="not simple"):
        mp3_decompose([(0, 0), (2, 2), (2, 0), (0, 2)])  # a bow tie


def test_verify_tiling_catches_a_gap():
    whole = Polygon([(0, 0), (2, 0), (2, 1), (0, 1)])
    with pytest.raises(DecompositionError, match="do not tile"):
        verify_tiling(whole, [Polygon([(0, 0), (1, 0), (1, 1), (0, 1)])])


# -------------------------------------------------------------------------------------------- extension
def test_extension_reproduces_the_thesis_example():
    shaft, arm = Polygon([(0, 0), (5, 0), (5, 10), (5, 15), (0, 15)]), Polygon([(5, 10), (20, 10), (20, 15), (5, 15)])
    shared = ((5.0, 10.0), (5.0, 15.0))
    # the arm extended into the shaft: the lines y = 10 and y = 15 go on to x = 0 (the first case of Sec. 4.2)
    assert _boxes([extend_into(arm, shaft, shared)]) == [(0, 10, 20, 15)]
    # the shaft extended into the arm: its lower edge's line x = 5 stops it (no area added)
    assert extend_into(shaft, arm, shared).area == pytest.approx(shaft.area)
    regions = extend_regions(mp3_decompose(L_THESIS, start=0))
    overlap = regions[0].polygon.intersection(regions[1].polygon)
    assert _boxes([overlap]) == [(0, 10, 5, 15)]  # Eq. 7: x > 0, y < 15, x < 5, y > 10


def test_extension_into_a_trapezoid_adds_the_triangle_of_converging_lines():
    # A's neighbouring edges converge inside B: the first case of the text adds their intersection point
    a = Polygon([(0, 0), (4, 1), (4, 3), (0, 4)])
    b = Polygon([(4, 1), (10, 0), (10, 4), (4, 3)])
    grown = extend_into(a, b, ((4.0, 1.0), (4.0, 3.0)))
    assert grown.convex_hull.area == pytest.approx(grown.area)
    assert grown.area == pytest.approx(Polygon([(0, 0), (8, 2), (0, 4)]).area)


@pytest.mark.parametrize("seed", range(8))
def test_extended_regions_are_convex_cover_the_pieces_and_stay_inside(seed):
    polygon, _ = orthogonal_polygon(np.random.default_rng(seed), notches=3 + seed)
    whole = Polygon(polygon)
    regions = extend_regions(mp3_decompose(polygon))
    for r in regions:
        assert r.polygon.convex_hull.area == pytest.approx(r.polygon.area, rel=1e-9)
        assert r.polygon.difference(whole).area < 1e-9
        assert r.piece.difference(r.polygon).area < 1e-9
    assert shapely.union_all([r.polygon for r in regions]).symmetric_difference(whole).area < 1e-9


# ----------------------------------------------------------------------------------- graph and automaton
def test_half_planes_describe_the_polygon():
    rows = half_planes(Polygon([(0, 0), (5, 0), (5, 15), (0, 15)]))
    assert sorted(rows) == sorted([(0.0, -1.0, 0.0), (1.0, 0.0, 5.0), (0.0, 1.0, 15.0), (-1.0, 0.0, 0.0)])


def test_l_map_automaton_has_the_thesis_structure():
    st = load_station("L")
    tmap = build_thesis_map(st, rule="region", clearance_m=0.0)
    assert len(tmap.regions) == 2 and list(tmap.graph.edges) == [(0, 1)]
    # the free space of the 0.3 m disc: shaft x in (0.3, 4.7), overlap x in (0.3, 4.7), y in (10.3, 14.7)
    assert _boxes([tmap.overlap(0, 1)]) == [(0.3, 10.3, 4.7, 14.7)]
    ha = build_automaton(tmap, k=1)
    n0, n1 = len(tmap.region_anchors[0]), len(tmap.region_anchors[1])
    assert len(ha.modes) == 2 + n0 + n1
    jumps = list(ha.jumps())
    assert len(jumps) == ha.n_jumps
    # inside a region every mode switches to every other; across the overlap both ways; init and final
    assert ha.n_jumps == n0 * (n0 - 1) + n1 * (n1 - 1) + 2 * n0 * n1 + n0 + n1
    cross = next(j for j in jumps if j.source.startswith("r0") and j.target.startswith("r1"))
    assert sorted(np.round(cross.guard, 9).tolist()) == sorted(np.round(half_planes(tmap.overlap(0, 1)), 9).tolist())
    with_two = build_automaton(tmap, k=2)
    assert len(with_two.modes) == 2 + n0 + n1 + n0 * (n0 - 1) // 2 + n1 * (n1 - 1) // 2


def test_region_rule_keeps_only_a_regions_own_wall_anchors():
    st = load_station("dead_end")
    by_region = build_thesis_map(st, rule="region").region_anchors
    by_sight = build_thesis_map(st, rule="line_of_sight").region_anchors
    tmap = build_thesis_map(st, rule="region")
    arm = tmap.regions_containing(st.cargo.start_m)[0]
    # the arm's own anchor is the one on its end wall; through its opening it sees hall anchors too
    assert [tuple(st.anchor_positions[a]) for a in by_region[arm]] == [(9.0, 16.0)]
    assert len(by_sight[arm]) > 1


@pytest.mark.parametrize("name", station_names())
def test_every_shipped_map_has_a_connected_region_graph(name):
    import networkx as nx

    tmap = build_thesis_map(load_station(name))
    assert nx.is_connected(tmap.graph)
    assert tmap.regions_containing(tmap.station.cargo.start_m) and tmap.goal_regions()


def test_bad_rule_is_a_typed_error():
    from planners.errors import PlannerError

    with pytest.raises(PlannerError, match="rule must be one of"):
        build_thesis_map(make_station(), rule="nearest")
