"""benchmarks/conjunct_weight.py: a small run end to end (two seeds of corridor, weight 0 and 0.3, one worker):
the episodes at weight 0 are those of the robustness benchmark's cell, and the table pairs the weights seed by
seed; the table's lost and gained seeds on synthetic cells."""

from __future__ import annotations

import json

import pytest

from benchmarks import conjunct_weight
from tests.paths import ROOT


def test_a_small_run_flies_the_benchmarks_episodes_and_resumes(tmp_path):
    argv = ["--scenarios", "corridor", "--weights", "0,0.3", "--seeds", "2", "--workers", "1", "--out", str(tmp_path)]
    conjunct_weight.main(argv)
    cells = {c["weight"]: c for c in map(json.loads, (tmp_path / "cells.jsonl").read_text().splitlines())}
    assert sorted(cells) == [0.0, 0.3] and all(len(c["episodes"]) == 2 for c in cells.values())
    published = next(c for c in map(json.loads, (ROOT / "results" / "robustness" / "cells.jsonl").read_text()
                                    .splitlines())
                     if (c["scenario"], c["stack"], c["axis"], c["level"]) == ("corridor", "all", "impact", 0.02))
    for mine, theirs in zip(cells[0.0]["episodes"], published["episodes"]):
        assert (mine["seed"], mine["success"], mine["robustness"]) == (theirs["seed"], theirs["success"],
                                                                     pytest.approx(theirs["robustness"], abs=1e-12))
    assert "| corridor | 2 / 2 | 2 / 2 |" in (tmp_path / "table.md").read_text()
    before = (tmp_path / "cells.jsonl").stat().st_mtime_ns
    conjunct_weight.main(argv)  # resumed: nothing flown again, the cells file not rewritten
    assert (tmp_path / "cells.jsonl").stat().st_mtime_ns == before


def test_the_table_names_the_seeds_lost_and_gained_against_weight_0():
    def cell(weight, successes):
        return {"scenario": "s", "weight": weight, "noise_mps": 0.02,
                "episodes": [{"seed": k, "success": ok} for k, ok in enumerate(successes)]}

    text = conjunct_weight.table([cell(0.0, [True, False, True]), cell(0.3, [False, True, True])])
    assert "| s | 2 / 3 | 2 / 3 -0 +1 |" in text and "| **all** | **2 / 3** | **2 / 3** |" in text


@pytest.mark.parametrize("argv, message", [(["--weights", "0,2"], "must lie in"), (["--weights", "a"], "numbers"),
                                           (["--seeds", "0"], "--seeds")])
def test_bad_arguments_are_usage_errors(argv, message, capsys):
    with pytest.raises(SystemExit) as info:
        conjunct_weight.main(argv)
    assert info.value.code == 2 and message in capsys.readouterr().err
