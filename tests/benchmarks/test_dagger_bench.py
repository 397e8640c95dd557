"""benchmarks/dagger.py's table on synthetic cells: a cell run with round selection reports its selected round's
evaluation, in a row of its own beside the last-round DAgger and BC; cells from before selection count as 0."""

from __future__ import annotations

from benchmarks import dagger as bench


def _row(k, success, robustness=0.1):
    return {"round": k, "beta": 0.5 ** k, "dataset_labels": 100 * (k + 1), "labels": 100, "replan_labels": 0,
            "replan_label_s": 0.0, "label_s": 1.0, "learner_label_mse": None if k == 0 else 0.1, "val_mse": 0.01,
            "replan_cap_episodes": 0, "wall_s": 10.0 * (k + 1), "eval_success": success,
            "eval": [{"seed": 1_000_000_000 + j, "success": j < round(2 * success), "robustness_m": robustness}
                     for j in range(2)]}


def _cell(method, seed, rows, select=None, chosen=None):
    cell = {"scenario": "corridor", "method": method, "seed": seed, "budget_episodes": 6, "rows": rows,
            "eval_episodes": 2}
    if select is not None:
        cell.update({"select_episodes": select, "selected_round": chosen})
    return cell


def test_a_selected_round_is_reported_in_its_own_row(monkeypatch):
    last = [_row(0, 0.5), _row(1, 1.0), _row(2, 0.0)]
    cells = [_cell("bc", 0, [_row(0, 0.5)]), _cell("dagger", 0, last),
             _cell("dagger", 0, last, select=10, chosen=1)]
    monkeypatch.setattr(bench, "_store", lambda: cells)
    text = bench.table()
    assert "| corridor | BC | 6 (100) | 50 (" in text
    assert "| corridor | DAgger | 6 (300) | 0 (" in text  # the last round
    assert "| corridor | DAgger, the best round on 10 validation episodes (rounds 1) | 6 (300) | 100 (" in text
    assert text.count("| corridor | 6 | 2 |") == 1  # the per-round lines once, for last-round DAgger


def test_cells_from_before_selection_have_selection_0_and_their_last_round():
    cell = _cell("dagger", 2, [_row(0, 0.5), _row(1, 1.0)])
    assert bench._key(cell) == ("corridor", 6, "dagger", 2, 0)
    assert bench._final(cell)["round"] == 1
    assert bench._final(dict(cell, selected_round=0, select_episodes=5))["round"] == 0
