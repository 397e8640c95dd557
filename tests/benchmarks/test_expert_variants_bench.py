"""benchmarks/expert_variants.py: a small run end to end (two seeds of corridor from seed 3, the baseline and both
options, one worker): the baseline's episodes are those of the robustness benchmark's cell, and a rerun resumes;
the table's lost and gained seeds on synthetic cells; the arguments checked."""

from __future__ import annotations

import json

import pytest

from benchmarks import expert_variants
from tests.paths import ROOT


def test_a_small_run_flies_the_benchmarks_episodes_and_resumes(tmp_path):
    argv = ["--scenarios", "corridor", "--variants", "baseline,both", "--first-seed", "3", "--seeds", "2",
            "--workers", "1", "--out", str(tmp_path)]
    expert_variants.main(argv)
    cells = {c["variant"]: c for c in map(json.loads, (tmp_path / "cells.jsonl").read_text().splitlines())}
    assert sorted(cells) == ["baseline", "both"]
    assert [e["seed"] for e in cells["both"]["episodes"]] == [3, 4]
    published = next(c for c in map(json.loads, (ROOT / "results" / "robustness" / "cells.jsonl").read_text()
                                    .splitlines())
                     if (c["scenario"], c["stack"], c["axis"], c["level"]) == ("corridor", "all", "impact", 0.02))
    theirs = {e["seed"]: e for e in published["episodes"]}
    for mine in cells["baseline"]["episodes"]:
        assert (mine["success"], mine["robustness"]) == (theirs[mine["seed"]]["success"],
                                                         pytest.approx(theirs[mine["seed"]]["robustness"], abs=1e-12))
    assert "| corridor | 2 / 2 | 2 / 2 |" in (tmp_path / "table.md").read_text()
    before = (tmp_path / "cells.jsonl").stat().st_mtime_ns
    expert_variants.main(argv)  # resumed: nothing flown again, the cells file not rewritten
    assert (tmp_path / "cells.jsonl").stat().st_mtime_ns == before


def test_each_variant_switches_its_options_on():
    base = expert_variants.config("baseline")
    assert not base.way_round and not base.mission.later_approaches
    assert expert_variants.config("way_round").way_round and not expert_variants.config("way_round").mission \
        .later_approaches
    assert expert_variants.config("later_approaches").mission.later_approaches
    both = expert_variants.config("both")
    assert both.way_round and both.mission.later_approaches


def test_the_table_names_the_seeds_lost_and_gained_against_the_baseline():
    def cell(variant, successes, first=0):
        return {"scenario": "s", "variant": variant, "noise_mps": 0.02, "first_seed": first,
                "episodes": [{"seed": first + k, "success": ok} for k, ok in enumerate(successes)]}

    text = expert_variants.table([cell("way_round", [False, True, True]), cell("baseline", [True, False, True]),
                                  cell("baseline", [True], first=3), cell("way_round", [False], first=3)])
    assert "| scenario | baseline | way_round |" in text  # the baseline first
    assert "| s | 3 / 4 | 2 / 4 -0,3 +1 |" in text and "| **all** | **3 / 4** | **2 / 4** |" in text


@pytest.mark.parametrize("argv, message", [(["--variants", "baseline,fast"], "unknown variants"),
                                           (["--noise", "a"], "numbers"), (["--noise", "-0.1"], ">= 0"),
                                           (["--seeds", "0"], "--seeds"), (["--first-seed", "-1"], "--first-seed")])
def test_bad_arguments_are_usage_errors(argv, message, capsys):
    with pytest.raises(SystemExit) as info:
        expert_variants.main(argv)
    assert info.value.code == 2 and message in capsys.readouterr().err
