"""benchmarks/family_rl.py at tiny sizes: the held-out set never overlaps the training tasks, the expert and each
training seed become cells flown on the same episodes, a rerun skips them, and the table compares them."""

from __future__ import annotations

import pytest

from tests.optional import requires
from tests.shipped_plans import path as committed_plan

pytestmark = requires("stable_baselines3")


def test_heldout_tasks_are_the_kept_tasks_and_the_shipped_scenario():
    from baselines.batched.family_ppo import FamilyPpoConfig
    from benchmarks import family_rl

    held = family_rl.heldout("throw_and_catch")
    names = [sc.name for sc, _ in held]
    assert names[-1] == "throw_and_catch_exp" and len(names) >= 2
    trained = {f"throw_and_catch_{seed}" for seed in FamilyPpoConfig("throw_and_catch").tasks}
    assert not trained & set(names)


def test_cells_rerun_and_table(tmp_path, monkeypatch):
    from benchmarks import family_rl
    from impact_env.transport.scenario import load_scenario
    from planners.plan import Plan

    monkeypatch.setattr(family_rl, "OUT", tmp_path / "results")
    monkeypatch.setattr(family_rl, "RUNS", tmp_path / "runs")
    shipped = load_scenario("throw_and_catch_exp")
    monkeypatch.setattr(family_rl, "heldout", lambda family: [(shipped, Plan.load(committed_plan("sr", shipped.name)))])
    kwargs = {"tasks": (1000, 1001), "frames": 64, "envs_per_task": 4, "eval_episodes": 1}
    import baselines.batched.family_ppo as fp

    real = fp.FamilyPpoConfig

    def small(*args, **kw):  # the trainer's batch at tiny sizes
        return real(*args, **{**kw, "n_steps": 8, "batch_size": 16, "n_epochs": 1, "checkpoint_frames": 32,
                              "hidden": (8,)})

    monkeypatch.setattr(fp, "FamilyPpoConfig", small)
    family_rl.run_family("throw_and_catch", [0], **kwargs)
    store = family_rl._store()
    assert len(store) == 2
    expert = store.get(("throw_and_catch", "expert", None))
    learned = store.get(("throw_and_catch", "family_ppo", 0))
    assert [e["seed"] for e in expert["episodes"]] == [e["seed"] for e in learned["episodes"]] == [1000]
    assert expert["episodes"][0]["success"] and learned["env_steps"] == 64
    before = (tmp_path / "results" / "cells.jsonl").read_text()
    family_rl.run_family("throw_and_catch", [0], **kwargs)  # done: nothing is flown or trained again
    assert (tmp_path / "results" / "cells.jsonl").read_text() == before
    text = family_rl.table()
    assert "| throw_and_catch | expert | 1 | 100 (100-100) of 1 |" in text
    assert "| throw_and_catch | family_ppo (1 seeds) | 1 |" in text and "| 64 | 2 |" in text


def test_unknown_family_is_a_usage_error():
    from benchmarks import family_rl

    with pytest.raises(SystemExit):
        family_rl.main(["--families", "nope"])
