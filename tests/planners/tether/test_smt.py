"""The thesis's pipeline with z3 (Sec. 4.4) and the .drh export."""

from __future__ import annotations

import pytest

from impact_env.tether.station import load_station
from planners.errors import PlannerError
from planners.tether.automaton import build_automaton, build_thesis_map, half_planes
from planners.tether.drh import automaton_drh, export_drh, parse_drh, subproblem_drh
from planners.tether.random_maps import random_station
from planners.tether.reachability import ReachabilityPlanner
from planners.tether.smt import SmtConfig, SmtNoPlanError, bounded_search, plan_smt
from tests.station_helpers import make_station

pytest.importorskip("z3")


def test_divide_and_conquer_plans_the_l_map_along_its_two_regions():
    st = load_station("L")
    plan = plan_smt(st, SmtConfig(rule="region"))
    plan.check(st)
    assert plan.stats["path"] == [0, 1] and plan.method.startswith("smt-divide-and-conquer")
    assert plan.switches >= ReachabilityPlanner(st).level_of(st.cargo.start_m)  # never fewer than the fewest


def test_dead_end_arm_thesis_rule_finds_no_plan_and_line_of_sight_does():
    st = load_station("dead_end")
    with pytest.raises(SmtNoPlanError, match="region rule"):
        plan_smt(st, SmtConfig(rule="region"))
    plan = plan_smt(st, SmtConfig(rule="line_of_sight"))
    plan.check(st)
    # the exact planner agrees that a plan exists
    assert ReachabilityPlanner(st).plan().switches <= plan.switches


@pytest.mark.parametrize("station", [
    make_station([[0, 0], [12, 0], [12, 3], [0, 3]], start=(1.5, 1.5), goal=(9.0, 1.5), anchors={"spacing_m": 2.5}),
    random_station(1, notches=3),
    random_station(3, notches=5),
], ids=["corridor", "random_1", "random_3"])
def test_fewest_pulls_agree_with_the_bounded_search(station):
    exact = ReachabilityPlanner(station).plan()
    result = bounded_search(station, max_pulls=exact.switches, config=SmtConfig(rule="line_of_sight"))
    assert result.pulls == exact.switches, result.answers
    assert all(result.answers[n] == "unsat" for n in range(exact.switches))
    result.plan.check(station)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["dead_end", "L"])
def test_fewest_pulls_agree_with_the_bounded_search_on_shipped_maps(name):
    st = load_station(name)
    exact = ReachabilityPlanner(st).plan()
    result = bounded_search(st, max_pulls=exact.switches, config=SmtConfig(rule="line_of_sight", timeout_s=600))
    finished = {n: a for n, a in result.answers.items() if a != "unknown"}
    assert all(a == "unsat" for n, a in finished.items() if n < exact.switches)
    if exact.switches in finished:
        assert finished[exact.switches] == "sat"


def test_bounded_search_is_unsat_on_the_bottom_wall_only_l_map():
    st = make_station(anchors={"spacing_m": 2.5, "walls": [0]})
    result = bounded_search(st, max_pulls=2, config=SmtConfig(rule="line_of_sight"))
    assert result.pulls is None and result.answers == {0: "unsat", 1: "unsat", 2: "unsat"}


def test_smt_config_is_validated():
    with pytest.raises(PlannerError, match="rule must be one of"):
        SmtConfig(rule="anchors")
    with pytest.raises(PlannerError, match="timeout_s"):
        SmtConfig(timeout_s=0)


# ----------------------------------------------------------------------------------------------- .drh
def test_drh_export_of_the_l_map_parses_with_the_documented_grammar(tmp_path):
    st = load_station("L")
    tmap = build_thesis_map(st, rule="region")
    ha = build_automaton(tmap, k=1)
    path = export_drh(ha, tmp_path / "L.drh", st.bounds, st.tf_s)
    parsed = parse_drh(path.read_text())
    assert parsed["variables"] == ["x", "y", "time"]
    assert len(parsed["modes"]) == len(ha.modes) and parsed["init"] == 1 and parsed["goal"] == 2
    assert sum(len(m["jumps"]) for m in parsed["modes"].values()) == ha.n_jumps
    assert parsed["modes"][2]["jumps"] == []  # the final mode has no jumps
    text = path.read_text()
    assert "sqrt((" in text and "d/dt[x] = 0;" in text  # Eq. 5 flows, and the zero flow of init and final


def test_drh_subproblem_with_two_anchor_modes_parses():
    st = load_station("L")
    tmap = build_thesis_map(st, rule="region")
    ha = build_automaton(tmap, k=2)
    text = subproblem_drh(ha, 0, st.cargo.start_m, half_planes(tmap.overlap(0, 1)), st.bounds, st.tf_s)
    parsed = parse_drh(text)
    n = len(tmap.region_anchors[0])
    assert len(parsed["modes"]) == 2 + n + n * (n - 1) // 2
    assert text.count(" + (") > 0  # two unit vectors summed in a two-anchor flow


def test_drh_parser_rejects_broken_files():
    good = "[0, 1] x;\n[0, 1] y;\n[0, 5] time;\n{ mode 1;\n invt: (x <= 1);\n flow: d/dt[x] = 0; d/dt[y] = 0;\n" \
           " jump:\n}\ninit: @1 (and (x = 0) (y = 0));\ngoal: @1 (x >= 1);\n"
    parse_drh(good)
    with pytest.raises(PlannerError, match="time"):
        parse_drh(good.replace("[0, 5] time;\n", ""))
    with pytest.raises(PlannerError, match="flows for"):
        parse_drh(good.replace(" d/dt[y] = 0;", ""))
    with pytest.raises(PlannerError, match="undefined mode"):
        parse_drh(good.replace("goal: @1", "goal: @7"))
    with pytest.raises(PlannerError, match="syntax error"):
        parse_drh(good.replace("(x <= 1)", "(x <= )"))


def test_full_automaton_export_refuses_millions_of_jumps():
    st = load_station("T")
    ha = build_automaton(build_thesis_map(st, rule="line_of_sight"), k=2)
    with pytest.raises(PlannerError, match="jumps"):
        automaton_drh(ha, st.bounds, st.tf_s)
