"""Expert versus learned (benchmarks/expert_vs_learned.py and its table): one episode of the expert and of the
random controller on throw_and_catch_exp (the shortest horizon), resumed to two; the table's statistics and
rows on synthetic cells with known scores."""

from __future__ import annotations

import json

import numpy as np
import pytest

from benchmarks import expert_vs_learned_table as table
from benchmarks.expert_vs_learned import FIRST_SEED, NOISE, cell_key, main
from impact_env.results_store import CellStore
from tests.optional import requires

pytestmark = requires("rliable")

SCENARIO = "throw_and_catch_exp"


def test_flies_the_learned_evaluations_episodes_and_resumes(tmp_path):
    from impact_env.controllers import RandomController
    from impact_env.rollout import run_episode
    from impact_env.transport.gym_env import TransportEnv

    out, learned = tmp_path / "out", tmp_path / "no_learned_runs.jsonl"
    args = ["--scenarios", SCENARIO, "--out", str(out), "--learned", str(learned), "--reps", "50"]
    main([*args, "--episodes", "1"])
    store = CellStore(out / "cells.jsonl", cell_key)
    expert, random = store.get(("expert", SCENARIO)), store.get(("random", SCENARIO))
    assert expert["first_seed"] == FIRST_SEED == 1_000_000 and expert["env_options"] == NOISE
    assert expert["plan"]["source"] == f"results/robustness/plans/{SCENARIO}.json"
    assert (out / "plans" / f"{SCENARIO}.json").exists()
    assert [e["seed"] for e in expert["episodes"]] == [FIRST_SEED] and expert["episodes"][0]["success"]
    assert expert["episodes"][0]["robustness"] == pytest.approx(0.4, abs=0.01)  # the plan's rho, 0.4
    # the random cell is the same episode as flying the controller by hand: same env options, same seed
    by_hand = run_episode(TransportEnv(SCENARIO, **NOISE), RandomController(), seed=FIRST_SEED)
    assert random["episodes"][0]["robustness"] == by_hand.robustness
    assert random["episodes"][0]["success"] == (by_hand.robustness > 0)
    summary = (out / "summary.md").read_text()
    assert f"| {SCENARIO} | expert | 100 [21, 100] |" in summary  # Wilson's 95 % interval of 1 of 1
    assert f"| {SCENARIO} | SB3 PPO | no finished run |" in summary

    main([*args, "--episodes", "2"])  # resumed: the first episode kept as it was, the next seed added
    again = CellStore(out / "cells.jsonl", cell_key).get(("expert", SCENARIO))
    assert again["episodes"][0] == expert["episodes"][0]
    assert [e["seed"] for e in again["episodes"]] == [FIRST_SEED, FIRST_SEED + 1]
    main([*args, "--episodes", "1", "--publish"])  # the table only: nothing flown, nothing dropped
    assert len(CellStore(out / "cells.jsonl", cell_key).get(("expert", SCENARIO))["episodes"]) == 2
    rows = json.loads((out / "summary.json").read_text())["rows"]
    assert [r["episodes"] for r in rows if r["controller"] == "expert"] == [2]


def test_bad_arguments_are_usage_errors(tmp_path):
    with pytest.raises(SystemExit):
        main(["--scenarios", "corridr", "--out", str(tmp_path)])
    with pytest.raises(SystemExit):
        main(["--episodes", "0", "--out", str(tmp_path)])


def test_wilson_interval_known_values():
    assert table.wilson_interval(10, 20) == pytest.approx((0.2993, 0.7007), abs=1e-4)
    assert table.wilson_interval(20, 20) == pytest.approx((0.8389, 1.0), abs=1e-4)
    assert table.wilson_interval(0, 20) == pytest.approx((0.0, 0.1611), abs=1e-4)
    with pytest.raises(ValueError, match="0 <= successes <= n"):
        table.wilson_interval(3, 2)


def flown_cell(controller: str, scenario: str, robustness: list[float]) -> dict:
    return {"controller": controller, "scenario": scenario, "first_seed": FIRST_SEED, "env_options": NOISE,
            "episodes": [{"seed": FIRST_SEED + i, "robustness": r, "success": r > 0} for i, r in enumerate(robustness)]}


def learned_cell(algorithm: str, task: str, seed: int, success: float, robustness: float,
                 budget: int = 10_000_000) -> dict:
    """A cell as benchmarks.rl_at_scale publishes it, with a chosen pymunk success rate and robustness."""
    score = {"success_rate": success, "robustness_mean": robustness}
    return {"algorithm": algorithm, "task": task, "seed": seed, "env_steps": budget, "budget_env_steps": budget,
            "wall_s": 600.0 * (seed + 1), "env_steps_per_s": 1000.0, "run": f"{algorithm}__{task}__s{seed}",
            "evaluation": {"episodes": 100, "batched": score, "pymunk": score}}


def test_table_joins_flown_and_learned_rows():
    flown = [flown_cell("expert", "corridor", [0.7, 0.7, 0.7, -0.1]), flown_cell("random", "corridor", [-3.0, -1.0])]
    learned = [learned_cell("sb3_ppo", "corridor", s, v, v - 0.5) for s, v in enumerate([0.0, 0.2, 0.4, 1.0])]
    mappo = learned_cell("mappo", "corridor", 0, 0.1, -1.0)
    mappo["evaluation"]["sampled"] = {"pymunk": {"success_rate": 0.6, "robustness_mean": 0.05}}
    learned += [mappo, learned_cell("mappo", "vmas/transport", 0, 1.0, float("nan"))]
    numbers = table.numbers(flown, learned, ["corridor", "relay"], reps=50)
    rows = numbers["rows"]
    assert [(r["scenario"], r["controller"], r["kind"]) for r in rows] == [
        ("corridor", "expert", "flown"), ("corridor", "SB3 PPO", "learned"), ("corridor", "MAPPO", "learned"),
        ("corridor", "IPPO", "missing"), ("corridor", "random", "flown"), ("relay", "SB3 PPO", "missing"),
        ("relay", "MAPPO", "missing"), ("relay", "IPPO", "missing")]
    expert, sb3, mappo_row = rows[0], rows[1], rows[2]
    assert expert["success"] == 0.75 and expert["success_ci"] == pytest.approx(table.wilson_interval(3, 4))
    assert expert["robustness"] == pytest.approx(0.5)
    assert expert["robustness_ci"][0] <= 0.5 <= expert["robustness_ci"][1] <= 0.7
    assert sb3["success"] == pytest.approx(0.3) and sb3["seeds"] == [0, 1, 2, 3]  # IQM of 0, 0.2, 0.4, 1
    assert sb3["robustness"] == pytest.approx(-0.2) and sb3["budget_env_steps"] == [10_000_000]
    assert mappo_row["success"] == pytest.approx(0.6) and mappo_row["policy"] == ["sampled"]
    overall = {o["controller"]: o for o in numbers["overall"]}
    assert list(overall) == ["expert", "SB3 PPO", "MAPPO", "IPPO", "random"] and overall["IPPO"]["kind"] == "missing"
    assert overall["expert"]["mean"] == 0.75 and overall["random"]["mean"] == 0.0
    assert overall["SB3 PPO"]["mean"] == pytest.approx(np.mean([0.0, 0.2, 0.4, 1.0]))
    assert overall["MAPPO"]["scenarios"] == ["corridor"]  # VMAS's task is not a shipped scenario

    text = table.markdown(numbers)
    assert "| corridor | expert | 75 [30, 95] | +0.500 [" in text
    assert ("| corridor | SB3 PPO | 30 [" in text and "| 4 seeds x 100 episodes, deterministic | 10M | "
            "25.0 (10.0-40.0) | 0,1,2,3 |" in text)
    assert "| corridor | MAPPO | 60 [60, 60] |" in text and "1 seed (fewer than 3) x 100 episodes, sampled" in text
    assert "| relay | IPPO | no finished run |" in text and "| IPPO | 0 | - | - | - | no finished run | - |" in text
    assert "one controller on the first 2-4 episodes" in text and "evaluated on the first 100 of" in text
    assert "| random | 1 | - | - | - | - | 0 [0, 66] (2 episodes, Wilson) |" in text


def test_write_docs_replaces_the_block_between_its_markers(tmp_path):
    (tmp_path / "summary.md").write_text("intro\n\n## Per scenario\n\n| a |\n")
    page = tmp_path / "page.md"
    page.write_text("# Page\n\nno markers\n")
    with pytest.raises(SystemExit, match="markers"):
        table.write_docs(tmp_path, page)
    page.write_text(f"# Page\n\n{table.DOCS_BEGIN}\nold\n{table.DOCS_END}\n\nafter\n")
    table.write_docs(tmp_path, page)
    table.write_docs(tmp_path, page)  # again: the same page
    assert page.read_text() == (f"# Page\n\n{table.DOCS_BEGIN}\nintro\n\n### Per scenario\n\n| a |\n"
                                f"{table.DOCS_END}\n\nafter\n")
