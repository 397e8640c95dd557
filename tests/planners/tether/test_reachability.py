"""The exact tether planner: plans on every shipped map, proofs of infeasibility, the one-pull sets checked
point by point, and a sweep over random orthogonal stations against a sampling search."""

from __future__ import annotations

import numpy as np
import pytest
import shapely

from impact_env.tether.station import load_station, station_names
from planners.errors import PlannerError
from planners.tether.errors import TetherInfeasibleError, TetherPlanCheckError
from planners.tether.geometry import free_space_polygon, pull_segment, visibility_polygon
from planners.tether.plan import Pull, TetherPlan
from planners.tether.random_maps import random_station
from planners.tether.reachability import ReachabilityConfig, ReachabilityPlanner, plan_reachability
from tests.station_helpers import make_station, station_dict


def sampled_search(station, planner, max_pulls: int, samples: int = 12, grid_m: float = 0.2) -> int | None:
    """An independent oracle: breadth-first search over pulls whose switch points are sampled along each pull
    (grid-deduplicated); the fewest pulls it finds into the planner's goal set, or None within ``max_pulls``."""
    goal = planner.levels[0]
    frontier = [np.asarray(station.cargo.start_m, float)]
    seen = {tuple(np.round(frontier[0] / grid_m).astype(int))}
    if goal.distance(shapely.Point(frontier[0])) < 1e-9:
        return 0
    for depth in range(1, max_pulls + 1):
        nxt = []
        for x in frontier:
            for a in planner.usable:
                seg = pull_segment(station, planner.free, x, a, planner.stop_m)
                if seg is None:
                    continue
                line = shapely.LineString(seg)
                if line.intersects(goal) and not line.intersection(goal).is_empty \
                        and line.intersection(goal).length > 1e-6:
                    return depth
                for t in np.linspace(0.0, 1.0, samples)[1:]:
                    y = seg[0] + t * (seg[1] - seg[0])
                    key = tuple(np.round(y / grid_m).astype(int))
                    if key not in seen:
                        seen.add(key)
                        nxt.append(y)
        frontier = nxt
        if not frontier:
            return None
    return None


# --------------------------------------------------------------------------------------- shipped maps
@pytest.mark.parametrize("name", station_names())
def test_every_shipped_map_has_a_checked_plan(name):
    st = load_station(name)
    planner = ReachabilityPlanner(st)
    plan = planner.plan()
    plan.check(st)  # the disc inside, the tether in line of sight, sampled every centimetre; ends in the goal
    assert plan.switches == len(plan.pulls) >= 1 and plan.method == "reachability"
    n = planner.level_of(st.cargo.start_m)
    assert n == plan.switches and planner.levels[n].distance(shapely.Point(st.cargo.start_m)) < 1e-6
    assert planner.levels[n - 1].distance(shapely.Point(st.cargo.start_m)) > 0  # not one pull fewer
    # warm: the same levels, the same plan
    again = planner.plan()
    assert again.pulls == plan.pulls


def test_l_map_needs_three_single_pulls():
    # up the shaft, along the arm, into the goal box: no single anchor carries the cargo out of the shaft and
    # through the goal in one straight pull, and no pull from the shaft's bottom sees the arm's walls
    plan = plan_reachability(load_station("L"))
    assert plan.switches == 3
    assert plan.path_length_m == pytest.approx(np.linalg.norm(np.diff(plan.waypoints(), axis=0), axis=1).sum())
    assert plan.travel_time_s(1) == pytest.approx(plan.path_length_m / 0.1 + 3 * 5.0)
    assert plan.travel_time_s(2) == pytest.approx(plan.path_length_m / 0.1 + 5.0)


def test_one_pull_in_a_corridor_and_none_from_inside_the_goal():
    corridor = [[0, 0], [12, 0], [12, 3], [0, 3]]
    st = make_station(corridor, start=(1.5, 1.5), goal=(9.0, 1.5), anchors={"points": [[12, 1.5]]})
    plan = plan_reachability(st)
    assert plan.anchors == [0] and plan.pulls[0].start_m == (1.5, 1.5)
    assert plan.end_m[1] == pytest.approx(1.5) and 8.5 < plan.end_m[0] < 9.5
    inside = plan_reachability(st, start=(9.0, 1.5))
    assert inside.pulls == [] and inside.switches == 0 and inside.travel_time_s(1) == 0.0


def test_l_map_with_anchors_on_the_bottom_wall_only_is_proved_infeasible():
    st = make_station(anchors={"spacing_m": 2.5, "walls": [0]})
    planner = ReachabilityPlanner(st)
    with pytest.raises(TetherInfeasibleError, match="stops growing") as err:
        planner.plan()
    cert = err.value.certificate
    assert cert["fixed_point"] and cert["start_distance_m"] > 0
    assert planner.fixed_point and planner.levels[-1].area == pytest.approx(cert["reachable_area_m2"])
    # the proof: one more level adds nothing
    frontier = planner.levels[-1]
    grown = shapely.union_all([frontier] + [planner.pre(a, frontier) for a in planner.usable])
    assert grown.difference(frontier).area < 1e-9


def test_goal_unreachable_behind_a_wall_without_anchors_is_proved_infeasible():
    # a U whose right arm holds the goal; every anchor is on the left arm's walls and pulls away from the goal
    u = [[0, 0], [9, 0], [9, 6], [6, 6], [6, 2], [3, 2], [3, 6], [0, 6]]
    st = make_station(u, start=(1.5, 4.0), goal=(7.5, 4.5), anchors={"spacing_m": 2.5, "walls": [6, 7]})
    with pytest.raises(TetherInfeasibleError):
        plan_reachability(st)


# ------------------------------------------------------------------------------ one pull, point by point
@pytest.mark.parametrize("name", ["L", "dead_end", "iss_chain"])
def test_pre_matches_a_direct_check_of_each_pull(name):
    st = load_station(name)
    planner = ReachabilityPlanner(st)
    target = planner.levels[0].buffer(1.5).intersection(planner.free)  # a set with some extent
    rng = np.random.default_rng(0)
    x0, x1, y0, y1 = st.bounds
    pts = np.column_stack([rng.uniform(x0, x1, 4000), rng.uniform(y0, y1, 4000)])
    pts = pts[shapely.contains_xy(planner.free, pts[:, 0], pts[:, 1])][:600]
    checked = 0
    for a in list(planner.usable)[::3]:
        pre = planner.pre(a, target)
        for x in pts:
            seg = pull_segment(st, planner.free, x, a, planner.stop_m)
            direct = seg is not None and shapely.LineString(seg).intersection(target).length > 1e-7
            margin = min(pre.boundary.distance(shapely.Point(x)) if not pre.is_empty else 1.0,
                         target.boundary.distance(shapely.Point(x)))
            if margin < 1e-4:
                continue  # on a boundary either answer is right
            assert direct == (pre.distance(shapely.Point(x)) < 1e-9), (a, x.tolist())
            checked += 1
    assert checked > 1000


def test_visibility_polygon_agrees_with_line_of_sight():
    st = load_station("alcove")
    rng = np.random.default_rng(1)
    x0, x1, y0, y1 = st.bounds
    pts = np.column_stack([rng.uniform(x0, x1, 3000), rng.uniform(y0, y1, 3000)])
    pts = pts[shapely.contains_xy(st.shapely_polygon, pts[:, 0], pts[:, 1])]
    for a in range(0, st.n_anchors, 4):
        vis = visibility_polygon(st, a)
        for x in pts[:300]:
            if vis.boundary.distance(shapely.Point(x)) < 1e-6:
                continue
            assert bool(vis.covers(shapely.Point(x))) == bool(st.line_of_sight(x, [a])[0]), (a, x.tolist())


# --------------------------------------------------------------------------------------- random stations
def _sweep(seed: int) -> None:
    """The station with anchors on every wall (a plan exists on all of these) and its variant with anchors on
    one wall only (nearly always infeasible: the proof must agree with the sampling search)."""
    _check_station(random_station(seed, notches=2 + seed % 19))
    _check_station(random_station(seed, notches=2 + seed % 19, walls=[0]))


def _check_station(st) -> None:
    planner = ReachabilityPlanner(st)
    try:
        plan = planner.plan()
    except TetherInfeasibleError as exc:
        assert exc.certificate["fixed_point"]
        assert sampled_search(st, planner, max_pulls=4) is None  # the oracle finds nothing either
        return
    plan.check(st)
    found = sampled_search(st, planner, max_pulls=plan.switches)
    # the oracle's switch points are samples, so it may need more pulls, never fewer
    assert found is None or found >= plan.switches


@pytest.mark.parametrize("seed", range(6))
def test_random_orthogonal_stations(seed):
    _sweep(seed)


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(6, 60))
def test_random_orthogonal_stations_sweep(seed):
    _sweep(seed)


# -------------------------------------------------------------------------------------- plan and config
def test_plan_json_round_trip_and_check_failures(tmp_path):
    st = load_station("L")
    plan = plan_reachability(st)
    back = TetherPlan.load(plan.save(tmp_path / "plan.json"))
    assert back.pulls == plan.pulls and back.goal_box == plan.goal_box and back.switches == plan.switches
    back.check(st)
    off = TetherPlan(**{**back.__dict__, "pulls": [Pull(back.pulls[0].anchor, back.pulls[0].start_m, (4.9, 5.0)),
                                                     *back.pulls[1:]]})
    with pytest.raises(TetherPlanCheckError) as err:
        off.check(st)
    assert any("straight toward" in v for v in err.value.violations)
    assert any("starts at" in v for v in err.value.violations)
    short = TetherPlan(**{**back.__dict__, "pulls": back.pulls[:-1]})
    with pytest.raises(TetherPlanCheckError, match="outside the goal box"):
        short.check(st)
    with pytest.raises(PlannerError, match="not a tether plan"):
        TetherPlan.from_dict({"format": "something else"})


def test_config_is_validated():
    with pytest.raises(PlannerError, match="clearance_m must be"):
        ReachabilityConfig(clearance_m=-1.0)
    with pytest.raises(PlannerError, match="max_pulls must be"):
        ReachabilityConfig(max_pulls=0)


def test_max_pulls_reached_is_not_a_proof():
    st = load_station("L")
    with pytest.raises(PlannerError, match="still grows") as err:
        ReachabilityPlanner(st, ReachabilityConfig(max_pulls=1)).plan()
    assert not isinstance(err.value, TetherInfeasibleError)


def test_free_space_is_inside_the_exact_one():
    st = make_station(**{k: v for k, v in station_dict().items() if False})
    mitred = free_space_polygon(st)
    assert mitred.difference(st.free_space(quad_segs=64)).area < 1e-6
    assert st.free_space().area - mitred.area == pytest.approx(0.3 ** 2 * (1 - np.pi / 4), rel=0.02)
