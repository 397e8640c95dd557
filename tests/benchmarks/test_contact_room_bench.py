"""benchmarks/contact_room.py's table: the re-plans' verdicts, then old and new plans paired on the same
episodes, and the refused tasks' old plans (synthetic cells; the re-planning and flying are the filter's and
the expert's, tested where they live)."""

from __future__ import annotations

from benchmarks import contact_room


def _verdict(name, kept, reason, rho=None, old=0.5, plan_s=10.0):
    return {"name": name, "kept": kept, "reason": reason, "robustness_m": rho, "old_robustness_m": old,
            "plan_s": plan_s}


def _flight(name, plan, success, condition="nominal", seed=0, robustness=0.1):
    return {"name": name, "plan": plan, "condition": condition, "seed": seed, "stack": "all", "success": success,
            "robustness": robustness if success else -robustness}


def test_the_table_pairs_old_and_new_plans_and_shows_what_refusing_loses():
    verdicts = [_verdict("a", True, "planned", 0.5), _verdict("b", True, "planned", 0.4, old=0.5, plan_s=30.0),
                _verdict("c", False, "no_plan_in_budget", plan_s=50.0)]
    flights = [_flight("a", "old", False), _flight("a", "new", True),
               _flight("b", "old", True), _flight("b", "new", True),
               _flight("c", "old", True),
               _flight("b", "new", False, seed=1)]  # no old flight on seed 1: not paired, not counted
    text = contact_room.table(verdicts, flights, flagged=3, kept=10)
    assert text.startswith("3 of 10 kept plans have a contact without room")
    assert "| 3 | 2 | no_plan_in_budget 1, planned 2 | 0.500 -> 0.450 | 30.0 |" in text
    rows = [line for line in text.splitlines() if line.startswith("| nominal |")]
    assert rows[0].startswith("| nominal | all | kept | old | 2 (2) | 50 (")
    assert rows[1].startswith("| nominal | all | kept | new | 2 (2) | 100 (") and "| 1 / 0 | 1.000 |" in rows[1]
    assert rows[2].startswith("| nominal | all | refused | old | 1 (1) | 100 (")
