"""The robustness grid's bars: the noise bar of the full stack and its gap to the paper's stack, on made cells."""

from __future__ import annotations

import pytest

from benchmarks import robustness, robustness_bars
from benchmarks.robustness_bars import Bars, gaps, missing, noise_rows, report
from impact_env.results_store import CellStore

STACKS = ("paper", "all")


def cell(scenario, stack, axis, level, wins, config=None):
    """A cell whose episode ``seed`` succeeded when ``wins[seed]``; flown with today's config unless given."""
    return {"scenario": scenario, "stack": stack, "axis": axis, "level": level,
            "config": config or robustness.config_fingerprint(stack),
            "episodes": [{"seed": s, "success": w, "robustness": 0.1 if w else -0.1, "robot_contacts": 0,
                          "mission_replans": 0, "replan_solve_s": []} for s, w in enumerate(wins)]}


@pytest.fixture(scope="module")
def fingerprints():
    return {stack: robustness.config_fingerprint(stack) for stack in STACKS}


def test_the_noise_bar_counts_the_full_stack_up_to_the_level_asked(fingerprints):
    bars = Bars(seeds=20)
    cells = [cell("relay", "all", "impact", 0.01, [True] * 20),
             cell("relay", "all", "impact", 0.02, [True] * 18 + [False] * 2),  # 90 %: fails
             cell("relay", "all", "impact", 0.03, [False] * 20),  # beyond the bar's levels
             cell("relay", "paper", "impact", 0.01, [False] * 20),  # not the full stack
             cell("corridor", "all", "impact", 0.02, [True] * 19 + [False])]  # 95 %: holds
    rows = noise_rows(cells, ["corridor", "relay"], fingerprints, bars)
    assert [(s, lv, ok) for s, lv, _, ok in rows] == [("corridor", 0.02, True), ("relay", 0.01, True),
                                                      ("relay", 0.02, False)]


def test_the_gap_to_the_paper_counts_the_shared_seeds_only_and_allows_one_episode(fingerprints):
    bars = Bars(seeds=4)
    cells = [cell("relay", "paper", "thrust", 0.1, [True, True, True, True, True, True]),
             cell("relay", "all", "thrust", 0.1, [True, False, True, True]),  # seeds 4, 5 only the paper flew
             cell("relay", "paper", "offset", 0.1, [True, True, False, True]),
             cell("relay", "all", "offset", 0.1, [False, True, True, False]),  # 2 below the paper on seeds 0, 3
             cell("relay", "all", "e", 0.1, [False, False])]  # the paper did not fly it: no gap
    found = {g.axis: g for g in gaps(cells, ["relay"], fingerprints, bars)}
    assert set(found) == {"offset", "thrust"}
    thrust, offset = found["thrust"], found["offset"]
    assert (thrust.shared, thrust.paper, thrust.all, thrust.paper_only) == (4, 4, 3, [1])
    assert thrust.holds(bars.slack)
    assert (offset.paper, offset.all, offset.paper_only, offset.all_only) == (3, 2, [0, 3], [2])
    assert offset.holds(bars.slack)  # 1 success below
    assert not offset.holds(0)
    worse = [cell("relay", "paper", "offset", 0.1, [True] * 4), cell("relay", "all", "offset", 0.1,
                                                                      [True, False, False, True])]
    assert not gaps(worse, ["relay"], fingerprints, bars)[0].holds(bars.slack)


def test_the_grid_names_missing_short_and_stale_cells(fingerprints):
    bars = Bars(seeds=3)
    cells = [cell("relay", stack, axis, level, [True] * robustness.cell_seeds(axis, 3))
             for stack in STACKS for axis in robustness_bars.BAR_AXES for level in robustness.AXES[axis]]
    assert missing(cells, ["relay"], fingerprints, bars) == []
    assert len(cells) == 2 * sum(len(robustness.AXES[a]) for a in robustness_bars.BAR_AXES)
    cells[0] = cell("relay", "paper", "e", 0.1, [True])  # the e axis needs 2
    cells[-1] = cell("relay", "all", "impact", 0.03, [True] * 3, config="0123456789ab")
    del cells[1]
    assert missing(cells, ["relay"], fingerprints, bars) == [
        ("relay", "paper", "e", 0.1, "1 episodes"), ("relay", "paper", "e", 0.2, "missing"),
        ("relay", "all", "impact", 0.03, "stale")]
    text, ok = report(cells, ["relay"], bars)
    assert not ok and "3 cells to fly" in text


def test_the_command_checks_a_folder_and_exits_1_when_a_bar_fails(tmp_path, capsys):
    store = CellStore(tmp_path / "cells.jsonl", key=robustness.key_of)
    store.put_many([cell("relay", stack, axis, level, [True] * robustness.cell_seeds(axis, 2))
                    for stack in STACKS for axis in robustness_bars.BAR_AXES for level in robustness.AXES[axis]])
    args = ["--out", str(tmp_path), "--scenarios", "relay", "--seeds", "2", "--check"]
    assert robustness_bars.main(args) == 0
    assert "grid: complete and current" in capsys.readouterr().out
    store.put_many([cell("relay", "all", "impact", 0.02, [True, False])])
    assert robustness_bars.main(args) == 1
    assert "noise bar: fails" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        robustness_bars.main(["--out", str(tmp_path / "nowhere")])
    assert "fly the grid with python -m benchmarks.robustness first" in capsys.readouterr().err
