"""The expert on generated tasks, this tree against a commit: the jobs of a folder, the table, a real run."""

from __future__ import annotations

import json
import shutil

import pytest

from benchmarks import generated_expert
from tests.paths import ROOT

TASKS = ROOT / "results" / "task_generator" / "throw_and_catch"


def small_folder(tmp_path, names=("throw_and_catch_0", "throw_and_catch_6"), dropped="throw_and_catch_11"):
    """A generator folder with two kept tasks of the committed run and one dropped verdict."""
    family = tmp_path / "tasks" / "throw_and_catch"
    family.mkdir(parents=True)
    verdicts = {json.loads(line)["name"]: line for line in (TASKS / "verdicts.jsonl").read_text().splitlines()}
    assert not json.loads(verdicts[dropped])["kept"]
    lines = []
    for name in names:
        shutil.copy(TASKS / f"{name}.toml", family)
        shutil.copy(TASKS / f"{name}.plan.json", family)
        lines.append(verdicts[name])
    (family / "verdicts.jsonl").write_text("\n".join([*lines, verdicts[dropped]]) + "\n")
    return tmp_path / "tasks"


def test_jobs_are_the_kept_tasks_times_the_seeds(tmp_path):
    folder = small_folder(tmp_path)
    jobs = generated_expert.kept_jobs(folder, "throw_and_catch", "all", "impact", 0.02, seeds=3)
    assert [(j["name"], j["seed"]) for j in jobs] == [(n, s) for n in ("throw_and_catch_0", "throw_and_catch_6")
                                                      for s in range(3)]
    assert jobs[0]["plan"] == json.loads((TASKS / "throw_and_catch_0.plan.json").read_text())
    (folder / "throw_and_catch" / "throw_and_catch_6.plan.json").unlink()  # a task without its plan is left out
    assert {j["name"] for j in generated_expert.kept_jobs(folder, "throw_and_catch", "all", "nominal", 0, 1)} == \
        {"throw_and_catch_0"}
    with pytest.raises(SystemExit, match="python -m benchmarks.task_generator --families gaps"):
        generated_expert.kept_jobs(folder, "gaps", "all", "nominal", 0, 1)


def cell(tree, name, seed, success, impacts=2):
    return {"tree": tree, "family": "throw_and_catch", "name": name, "stack": "all", "axis": "nominal",
            "level": 0.0, "seed": seed, "success": success, "robustness": 0.1 if success else -1.0,
            "impacts": impacts, "planned_impacts": 2, "ms_per_step": 2.0}


def test_the_table_pairs_the_episodes_with_the_ref():
    new = [cell("new", f"t{i}", 0, i < 8, impacts=3 if i == 9 else 2) for i in range(10)]
    old = [cell("old", f"t{i}", 0, i < 5) for i in range(10)]
    text = generated_expert.table(new + old, ref="old").splitlines()
    assert text[2].startswith("| throw_and_catch | nominal | new (all) | 10 (10) | 80 (49-94) |")
    assert "| 1 | 2.0 | 3 / 0 of 10 | 0.250 |" in text[2]  # tasks t5-t7 only the new tree delivers
    assert text[3].startswith("| throw_and_catch | nominal | old (ref) (all) | 10 (10) | 50 (24-76) |")


def test_bad_arguments_are_usage_errors(capsys):
    for args, message in ((["--level", "0.02"], "--level needs an --axis"),
                          (["--axis", "impact"], "needs a --level > 0"), (["--seeds", "0"], "at least 1")):
        with pytest.raises(SystemExit):
            generated_expert.main(args)
        assert message in capsys.readouterr().err


@pytest.mark.slow
def test_a_commit_exported_flies_the_same_episodes_as_this_checkout_of_it(tmp_path):
    """Two kept tasks flown by this checkout and by HEAD exported (its pure-Python paths, in a child process of
    its own): when impact_env/ and planners/ are HEAD's, every record but the timings agrees; the command
    resumes with nothing left to fly, and a ref that is this checkout's commit is flown once."""
    from benchmarks.git_tree import export_tree
    from impact_env.results_store import CellStore

    folder = small_folder(tmp_path)
    if generated_expert.commit_of(None).endswith("+dirty"):
        pytest.skip("impact_env/ or planners/ are edited: this checkout is not HEAD")
    store = CellStore(tmp_path / "cells.jsonl", key=generated_expert.key_of)
    jobs = generated_expert.kept_jobs(folder, "throw_and_catch", "all", "nominal", 0.0, seeds=1)
    generated_expert.fly_trees(jobs, {"here": str(ROOT), "head": export_tree("HEAD")}, store, workers=2, chunk=1)
    by_tree: dict[str, dict] = {}
    for c in store.cells():
        by_tree.setdefault(c["tree"], {})[c["name"]] = {k: v for k, v in c.items()
                                                        if k not in ("tree", "wall_s", "ms_per_step")}
    assert set(by_tree) == {"here", "head"} and len(by_tree["here"]) == 2
    assert by_tree["here"] == by_tree["head"]
    out = tmp_path / "out"
    args = ["--tasks", str(folder), "--ref", "HEAD", "--workers", "1", "--out", str(out)]
    assert generated_expert.main(args) == 0
    assert len((out / "cells.jsonl").read_text().splitlines()) == 2  # HEAD is this checkout: flown once
    assert (out / "table.md").read_text().count("\n") == 3
    assert generated_expert.main(args) == 0  # resumed: nothing left to fly
