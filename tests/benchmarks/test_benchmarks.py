"""The benchmarks as modules: the per-cell conversion (every number kept), resume from cells.jsonl, ``python -m
benchmarks.X``, another commit's tree in a subprocess, Ray's by-value jobs, and no ``sys.path`` edits."""

from __future__ import annotations

import ast
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from benchmarks import convert_cells, impact_robust, robustness
from benchmarks.git_tree import run_in_tree
from impact_env.results_store import CellStore
from tests.paths import DATA, ROOT

BEFORE = DATA / "cells_before"  # per-cell files as the benchmarks wrote them before cells.jsonl (same bytes)


def old_folder(tmp_path: Path, benchmark: str) -> Path:
    folder = tmp_path / "old"
    shutil.copytree(BEFORE / benchmark, folder)
    return folder


def test_converted_robustness_cells_are_the_old_files_line_for_line(tmp_path):
    folder = old_folder(tmp_path, "robustness")
    shutil.copy(DATA / "plans" / "robustness" / "relay.json", folder / "relay__plan.json")
    texts = {p.name: p.read_text() for p in folder.glob("*__*__*.json")}
    assert convert_cells.main(["robustness", str(folder), "--out", str(tmp_path / "new"), "--delete"]) == 0
    assert not folder.exists()  # every old file removed, once checked
    new = tmp_path / "new"
    assert (new / "plans" / "relay.json").read_bytes() == (DATA / "plans" / "robustness" / "relay.json").read_bytes()
    lines = (new / "cells.jsonl").read_text().splitlines()
    assert sorted(lines) == sorted(texts.values())  # each old file's text is its cell's line
    store = robustness.cell_store(new)
    # a few of the originals' values, as measured
    e01 = store.get(robustness.cell_key("corridor", "paper", "e", 0.1))
    assert [(e["seed"], e["robustness"], e["wall_s"]) for e in e01["episodes"]] == [
        (0, 0.7303667214087399, 2.1670460770001228), (1, 0.7495507999355056, 2.0506656969992036)]
    combined = store.get(robustness.cell_key("two_objects", "+mission", "combined", 0.0))
    assert combined["episodes_requested"] == 50 and len(combined["episodes"]) == 50
    assert combined["episodes"][0]["robustness"] == -0.08050865804549634
    assert combined["episodes"][0]["replan_solve_s"][:2] == [0.5694554559959215, 0.44680192899977555]
    for name, text in texts.items():
        old = json.loads(text)
        assert store.get(robustness.key_of(old)) == old, name
    table = (new / "table.md").read_text()
    assert table == robustness.table(store.cells(), robustness.all_scenarios(store.cells())) + "\n"
    assert "| corridor | e +-0.1 | paper | 2 | 100% | +0.740 (+0.730) |" in table


def test_converted_impact_robust_cells_and_plans(tmp_path):
    folder = old_folder(tmp_path, "impact_robust")
    shutil.copy(DATA / "plans" / "ir" / "corridor.json", folder / "corridor__ir_plan.json")
    texts = {p.name: p.read_text() for p in folder.glob("*__*__*__*.json")}
    convert_cells.convert("impact_robust", folder, folder)  # in place, old files kept
    assert (folder / "plans" / "ir" / "corridor.json").read_bytes() == (folder / "corridor__ir_plan.json").read_bytes()
    store = impact_robust.cell_store(folder)
    assert sorted(json.dumps(c) for c in store) == sorted(texts.values())
    level = json.loads(texts["throw_and_catch_exp__ir__paper__noise_+0.0500.json"])["level"]
    noise = store.get(impact_robust.cell_key("throw_and_catch_exp", "ir", "paper", "noise", level))
    assert noise is not None and level != 0.05  # keyed by the level itself, not its 4 decimals in the file name
    assert store.get(impact_robust.cell_key("throw_and_catch_exp", "ir", "paper", "noise", 0.05)) is None
    assert store.get(impact_robust.cell_key("corridor", "sr", "all", "e", 0.1))["episodes"][0]["robustness"] == \
        json.loads(texts["corridor__sr__all__e_+0.1000.json"])["episodes"][0]["robustness"]
    with pytest.raises(SystemExit, match="exists already"):
        convert_cells.convert("impact_robust", folder, folder)


def test_a_benchmark_refuses_an_old_folder_with_the_command_that_converts_it(tmp_path):
    folder = old_folder(tmp_path, "robustness")
    with pytest.raises(SystemExit, match=f"python -m benchmarks.convert_cells robustness {folder} --out {folder}"):
        robustness.cell_store(folder)
    # a plan cached there the old way is still read (no planning)
    shutil.copy(DATA / "plans" / "robustness" / "relay.json", folder / "relay__plan.json")
    assert robustness.plan_for("relay", folder) == json.loads((folder / "relay__plan.json").read_text())


class FakeEngine:
    """Flies nothing: records the jobs and answers each with a made-up episode."""

    def __init__(self) -> None:
        self.jobs: list = []

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        pass

    def map(self, fn, jobs):
        jobs = list(jobs)
        self.jobs += jobs
        return [{"seed": j[-1], "success": True, "robustness": 0.5, "robot_contacts": 0, "mission_replans": 0,
                 "replan_solve_s": []} for j in jobs]


def test_the_robustness_benchmark_skips_the_cells_done_and_reruns_a_cell_asked_for_more_seeds(tmp_path,
                                                                                                monkeypatch):
    out = tmp_path / "out"
    convert_cells.convert("robustness", old_folder(tmp_path, "robustness"), out)
    (out / "plans").mkdir()
    shutil.copy(DATA / "plans" / "robustness" / "relay.json", out / "plans" / "relay.json")  # no planning
    before = (out / "cells.jsonl").read_text().splitlines()
    engine = FakeEngine()
    monkeypatch.setattr(robustness, "open_engine", lambda config: engine)
    grid = dict(scenarios=["relay"], stacks=["all"], axes=["offset"], seeds_shipped=50, out=out, engine=None,
                levels={"offset": (0.2,)})
    robustness.run(seeds_new=10, **grid)  # relay all offset 0.2 has its 10 episodes: only nominal is flown
    assert [(j[0], j[1], j[3], j[4], j[5]) for j in engine.jobs] == [("relay", "all", "nominal", 0.0, 0)]
    lines = (out / "cells.jsonl").read_text().splitlines()
    assert lines[:len(before)] == before and len(lines) == len(before) + 1
    assert "| relay | nominal | all | 1 | 100% | +0.500 (+0.500) |" in (out / "table.md").read_text()
    engine.jobs.clear()
    robustness.run(seeds_new=10, **grid)
    assert engine.jobs == []  # everything done
    old = robustness.cell_store(out).get(robustness.cell_key("relay", "all", "offset", 0.2))
    robustness.run(seeds_new=25, **grid)  # more seeds asked: the missing ones are flown, the cell replaced in place
    assert [j[5] for j in engine.jobs] == list(range(10, 25))
    store = robustness.cell_store(out)
    assert store.keys()[:len(before)] == [robustness.key_of(json.loads(line)) for line in before]  # in place
    assert len(store) == len(before) + 1
    cell = store.get(robustness.cell_key("relay", "all", "offset", 0.2))
    assert cell["episodes_requested"] == 25 and cell["episodes"][:10] == old["episodes"]
    assert [e["seed"] for e in cell["episodes"]] == list(range(25))
    assert cell["config"] == robustness.config_fingerprint("all")
    engine.jobs.clear()
    robustness.run(seeds_new=25, stale=("all",), **grid)  # stamped with today's config: not stale
    assert engine.jobs == []
    store.put({**cell, "config": "another"})
    robustness.run(seeds_new=25, stale=("all",), **grid)  # flown with another config: flown again whole
    assert [j[5] for j in engine.jobs] == list(range(25))  # (the nominal cell, flown by this run, is not)
    engine.jobs.clear()
    robustness.run(seeds_new=25, stale=("paper",), **grid)  # only the stacks named are stale
    assert engine.jobs == []


def test_the_identification_error_column():
    cell = {"episodes": [{"identification": {"R1-O1": {"estimate": 0.5, "error": -0.1},
                                             "R2-O1": {"estimate": 0.62, "error": 0.02}}},
                         {"identification": {"R1-O1": {"estimate": 0.6, "error": 0.0},
                                             "R2-O1": {"estimate": 0.63, "error": 0.03}}}]}
    assert robustness.identification_error(cell) == "0.065 / 0.100"
    assert robustness.identification_error({"episodes": [{"identification": None}, {}]}) == "-"
    assert robustness.config_fingerprint("paper") != robustness.config_fingerprint("all")


def test_cells_flown_with_another_config_are_marked():
    """A cell without a config counts as flown with its stack's config on main before cells recorded it: the
    paper's stack's is today's (unmarked), the full stack's is not (marked, with the note)."""
    episodes = [{"seed": 0, "success": True, "robustness": 0.5, "robot_contacts": 0, "mission_replans": 0,
                 "replan_solve_s": []}]
    stamped = {"config": robustness.config_fingerprint("+id")}
    cells = [{"scenario": "relay", "stack": stack, "axis": "nominal", "level": 0.0, "episodes": episodes, **extra}
             for stack, extra in (("paper", {}), ("all", {}), ("+id", stamped))]
    text = robustness.table(cells, ["relay"])
    assert "| relay | nominal | paper | 1 |" in text and "| relay | nominal | all * | 1 |" in text
    assert "| relay | nominal | +id | 1 |" in text and text.endswith("flies it again)")
    # flown with the paper's config of then, whose flights today's config flies too (SAME_FLIGHTS)
    assert robustness.flown_with(cells[0]) == robustness.UNSTAMPED_CONFIG["paper"]
    assert robustness.counts_as(cells[0]) == robustness.config_fingerprint("paper")
    assert robustness.counts_as(cells[1]) == robustness.UNSTAMPED_CONFIG["all"]


class FakePool(FakeEngine):
    """The impact-robust benchmark's process pool, flying nothing (each job answered with a made-up episode)."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__()
        FakePool.last = self

    def map(self, fn, jobs):
        jobs = list(jobs)
        self.jobs += jobs
        return [{"seed": j[-1], "success": True, "robustness": 0.2, "impacts": 2, "final_speed": 0.01,
                 "in_final_box": True, "mission_replans": 0, "wall_s": 0.0} for j in jobs]


def test_the_impact_robust_benchmark_flies_a_part_of_the_grid_and_again_the_cells_of_another_config(tmp_path,
                                                                                                   monkeypatch):
    out = tmp_path / "ir"
    for planner, source in (("sr", DATA / "plans" / "bench"), ("ir", DATA / "plans" / "ir")):
        (out / "plans" / planner).mkdir(parents=True)
        shutil.copy(source / "throw_and_catch_exp.json", out / "plans" / planner)  # no planning
    monkeypatch.setattr(impact_robust, "ProcessPoolExecutor", FakePool)
    grid = dict(scenarios=["throw_and_catch_exp"], stacks=["all", "paper"], seeds=3, out=out, workers=1)
    impact_robust.run(factors=(1.0,), planners=("ir",), **grid)  # the guarantee's cells only
    delta = json.loads((out / "plans" / "ir" / "throw_and_catch_exp.json").read_text())["delta_mps"]
    assert [(j[1], j[2], j[4], j[5], j[6]) for j in FakePool.last.jobs] == [
        ("ir", stack, "noise", delta, seed) for stack in ("all", "paper") for seed in range(3)]
    store = impact_robust.cell_store(out)
    assert len(store) == 2 and all(c["config"] == impact_robust.config_fingerprint(c["stack"]) for c in store.cells())
    impact_robust.run(factors=(1.0,), planners=("ir",), stale=("all", "paper"), **grid)
    assert FakePool.last.jobs == []  # flown with today's configs: not stale
    cell = store.get(impact_robust.cell_key("throw_and_catch_exp", "ir", "all", "noise", delta))
    store.put({key: value for key, value in cell.items() if key != "config"})  # as cells before 0.4
    assert "| throw_and_catch_exp | impact noise 1 delta (0.05 m/s) | all * | ir | 3 |" in impact_robust.table(
        store.cells(), ["throw_and_catch_exp"])
    impact_robust.run(factors=(1.0,), planners=("ir",), **grid)
    assert FakePool.last.jobs == []  # not asked to fly it again
    impact_robust.run(factors=(1.0,), planners=("ir",), stale=("all",), **grid)
    assert [(j[2], j[6]) for j in FakePool.last.jobs] == [("all", 0), ("all", 1), ("all", 2)]
    assert "*" not in impact_robust.table(impact_robust.cell_store(out).cells(), ["throw_and_catch_exp"])
    impact_robust.run(**{**grid, "seeds": 5, "stacks": ["paper"]}, factors=(1.0,), planners=("ir",))
    assert [j[6] for j in FakePool.last.jobs] == [3, 4]  # more seeds asked: only the missing ones flown
    cell = impact_robust.cell_store(out).get(impact_robust.cell_key("throw_and_catch_exp", "ir", "paper", "noise",
                                                                   delta))
    assert cell["episodes_requested"] == 5 and [e["seed"] for e in cell["episodes"]] == list(range(5))
    assert [c[:3] for c in impact_robust.conditions(0.01, 50)[:2]] == [("nominal", 0.0, 1), ("noise", 0.01, 50)]
    identified = {**cell, "episodes": [{**e, "identification": {"R1-O1": {"estimate": 0.47, "error": 0.0},
                                                                "R2-O1": {"estimate": 0.5, "error": -0.03}}}
                                       for e in cell["episodes"]]}
    assert impact_robust.row(identified).endswith("| 0.00 | 0.030 / 0.030 |")  # the estimates' error column
    assert impact_robust.row(cell).endswith("| 0.00 | - |")  # none recorded


def test_an_impact_robust_cell_of_a_plan_with_a_delta_that_moved_little_is_not_taken_as_done(tmp_path,
                                                                                                monkeypatch):
    """obstacle_avoidance's IR plan moved from delta 0.0249998 to 0.0249948 m/s: the same 4 decimals, which the
    key was, so the new plan's 1 x delta cell was found done (the old plan's) and never flown."""
    old_delta, new_delta = 0.024999800000000003, 0.024994800000000015
    assert impact_robust.cell_key("o", "ir", "all", "noise", old_delta) != \
        impact_robust.cell_key("o", "ir", "all", "noise", new_delta)
    assert impact_robust.cell_key("o", "ir", "all", "noise", -0.0) == impact_robust.cell_key("o", "ir", "all",
                                                                                             "noise", 0.0)
    out = tmp_path / "ir"
    for planner, source in (("sr", DATA / "plans" / "bench"), ("ir", DATA / "plans" / "ir")):
        (out / "plans" / planner).mkdir(parents=True)
        shutil.copy(source / "throw_and_catch_exp.json", out / "plans" / planner)  # no planning
    delta = json.loads((out / "plans" / "ir" / "throw_and_catch_exp.json").read_text())["delta_mps"]
    earlier = delta + 2e-5  # another plan's delta, equal to 4 decimals
    assert f"{earlier:+.4f}" == f"{delta:+.4f}"
    episode = {"seed": 0, "success": False, "robustness": -0.1, "impacts": 2, "final_speed": 0.01,
               "in_final_box": False, "mission_replans": 0, "wall_s": 0.0}
    impact_robust.cell_store(out).put({"scenario": "throw_and_catch_exp", "planner": "ir", "stack": "all",
                                       "axis": "noise", "level": earlier, "delta": earlier, "episodes_requested": 1,
                                       "episodes": [episode], "wall_s": 0.0,
                                       "config": impact_robust.config_fingerprint("all")})
    monkeypatch.setattr(impact_robust, "ProcessPoolExecutor", FakePool)
    impact_robust.run(["throw_and_catch_exp"], ["all"], 1, out, 1, factors=(1.0,), planners=("ir",))
    assert [(j[5], j[6]) for j in FakePool.last.jobs] == [(delta, 0)]  # today's plan's cell is flown
    cells = impact_robust.cell_store(out).cells()
    assert sorted(c["level"] for c in cells) == [delta, earlier]  # and the earlier plan's is kept beside it
    assert " † |" in impact_robust.table(cells, ["throw_and_catch_exp"], impact_robust.plan_deltas(out))
    flown = impact_robust.cell_store(out).get(impact_robust.cell_key("throw_and_catch_exp", "ir", "all", "noise",
                                                                     delta))
    assert flown["plan"] == impact_robust.plan_fingerprint(json.loads(
        (out / "plans" / "ir" / "throw_and_catch_exp.json").read_text()))
    # another plan with the very same delta (corridor's, planned again with the obstacle rows): flown again whole
    impact_robust.cell_store(out).put({**flown, "plan": "0123456789ab", "episodes": [episode]})
    here = (impact_robust.plan_deltas(out), impact_robust.plan_fingerprints(out))
    text = impact_robust.table(impact_robust.cell_store(out).cells(), ["throw_and_catch_exp"], *here)
    assert "| all † | ir |" in text
    impact_robust.run(["throw_and_catch_exp"], ["all"], 1, out, 1, factors=(1.0,), planners=("ir",))
    assert [(j[5], j[6]) for j in FakePool.last.jobs] == [(delta, 0)]
    rows = impact_robust.table(impact_robust.cell_store(out).cells(), ["throw_and_catch_exp"], *here).splitlines()
    assert [r.split(" | ")[2] for r in rows[2:4]] == ["all", "all †"]  # today's plan's cell, the earlier one's


def test_the_fingerprint_names_the_planner_defaults_of_the_stacks_that_re_plan(monkeypatch):
    """A mission re-plan and a station-keeping trim build PlannerConfig() and an IRPlannerConfig with their
    defaults: a change of those marks the cells of the stacks that re-plan stale, not the others'."""
    from planners.offline import config

    before = {stack: robustness.config_fingerprint(stack) for stack in robustness.STACKS}
    before_ir = {stack: impact_robust.config_fingerprint(stack) for stack in impact_robust.STACKS}
    assert before["paper"] == robustness.expert_only_fingerprint("paper")  # the paper's stack re-plans nothing
    assert before["all"] != robustness.expert_only_fingerprint("all")
    assert before_ir["all"] == before["all"]
    monkeypatch.setattr(config, "DEFAULT_IR_NODE_BUDGET", config.DEFAULT_IR_NODE_BUDGET + 1)
    after = {stack: robustness.config_fingerprint(stack) for stack in robustness.STACKS}
    assert [s for s in robustness.STACKS if after[s] != before[s]] == ["+mission", "all"]
    assert {s for s in impact_robust.STACKS if impact_robust.config_fingerprint(s) != before_ir[s]} == {
        "all", "all+sig"}
    monkeypatch.undo()
    monkeypatch.setattr(config, "DEFAULT_NODE_BUDGET", config.DEFAULT_NODE_BUDGET + 1)  # the SR re-plans'
    assert robustness.config_fingerprint("all") != before["all"]
    assert robustness.config_fingerprint("paper") == before["paper"]


def test_restamp_stamps_the_cells_of_todays_config_under_the_old_formula_and_nothing_else(tmp_path, monkeypatch):
    out = tmp_path / "rob"
    episodes = [{"seed": 0, "success": True, "robustness": 0.5, "robot_contacts": 0, "mission_replans": 0,
                 "replan_solve_s": []}]
    old_all = robustness.expert_only_fingerprint("all")

    def cell(stack, level, **extra):
        return {"scenario": "relay", "stack": stack, "axis": "offset", "level": level, "episodes_requested": 1,
                "episodes": episodes, "wall_s": 1.0, **extra}

    cells = [cell("all", 0.05, config=old_all), cell("all", 0.1, config="0123456789ab"), cell("all", 0.15),
             cell("paper", 0.05, config="3720cb004e2e"), cell("paper", 0.1),
             cell("+mission", 0.05, config=robustness.expert_only_fingerprint("+mission"))]
    cells.append(cell("all", 0.2, config=old_all))  # flown before the planner defaults last changed
    before = CellStore(tmp_path / "before.jsonl", robustness.key_of)
    before.put_many([cells[-1], {**cells[0], "episodes": [{**episodes[0], "robustness": 0.4}]}])  # 0.05: since
    store = robustness.cell_store(out)
    for c in cells:
        store.put(c)
    lines = (out / "cells.jsonl").read_text().splitlines()
    changed = robustness.restamp_expert_only(store, ["all", "paper"], before=before)
    assert [(c["stack"], c["level"]) for c in changed] == [("all", 0.05)]
    again = (out / "cells.jsonl").read_text().splitlines()
    assert again[1:] == lines[1:]  # the others byte for byte
    first = robustness.cell_store(out).get(robustness.cell_key("relay", "all", "offset", 0.05))
    assert first == {**cells[0], "config": robustness.config_fingerprint("all"), "restamped_from": old_all}
    assert "| relay | start within 5 cm | all |" in robustness.table(robustness.cell_store(out).cells(), ["relay"])
    assert robustness.restamp_expert_only(robustness.cell_store(out), ["all", "paper"], before=before) == []
    monkeypatch.setattr(sys, "argv", ["robustness", "--restamp", "+mission", "--out", str(out), "--flown-after",
                                      str(tmp_path / "before.jsonl")])
    robustness.main()
    assert robustness.cell_store(out).get(robustness.cell_key("relay", "+mission", "offset", 0.05))["config"] == \
        robustness.config_fingerprint("+mission") != robustness.expert_only_fingerprint("+mission")
    # the impact-robust benchmark's: a cell without a config is not today's there, so it stays unstamped
    ir_out = tmp_path / "ir"
    ir_store = impact_robust.cell_store(ir_out)
    base = {"scenario": "corridor", "planner": "ir", "axis": "noise", "delta": 0.025, "episodes_requested": 1,
            "episodes": [], "wall_s": 0.0}
    ir_store.put({**base, "stack": "all", "level": 0.025, "config": impact_robust.expert_only_fingerprint("all")})
    ir_store.put({**base, "stack": "all", "level": 0.05})
    assert [c["level"] for c in impact_robust.restamp(ir_store, ["all", "paper"])] == [0.025]
    assert [c.get("config") for c in impact_robust.cell_store(ir_out).cells()] == [
        impact_robust.config_fingerprint("all"), None]


def test_benchmarks_run_as_modules(tmp_path):
    out = tmp_path / "cells"
    convert_cells.convert("robustness", old_folder(tmp_path, "robustness"), out)
    (out / "table.md").unlink()
    done = subprocess.run([sys.executable, "-m", "benchmarks.robustness", "--table-only", "--scenarios",
                           "corridor", "--out", str(out)], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines()[2].startswith("| corridor | e +-0.1 | paper | 2 | 100% |")
    # header, rule, the three cells; the two that are not the paper's stack's were flown with its 0.3 config
    assert (out / "table.md").read_text().count("\n") == 7 and "flies it again)" in (out / "table.md").read_text()
    done = subprocess.run([sys.executable, "-m", "benchmarks.robustness_reproduce", "--help"], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0 and "--results" in done.stdout, done.stderr


def test_a_function_runs_under_another_tree_in_a_subprocess(tmp_path):
    for package in ("impact_env", "planners"):
        (tmp_path / package).mkdir()
        (tmp_path / package / "__init__.py").write_text("")
    origins = run_in_tree(tmp_path, "benchmarks.git_tree:package_origins")
    assert origins == {"impact_env": str(tmp_path / "impact_env"), "planners": str(tmp_path / "planners")}
    here = run_in_tree(ROOT, "benchmarks.git_tree:package_origins")
    assert here == {"impact_env": str(ROOT / "impact_env"), "planners": str(ROOT / "planners")}
    with pytest.raises(RuntimeError, match="benchmarks.git_tree:no_such_function under .* exited with status 1"):
        run_in_tree(tmp_path, "benchmarks.git_tree:no_such_function")


def test_on_ray_the_benchmarks_job_functions_travel_by_value(tmp_path):
    """A cluster's nodes have the installed packages, not benchmarks/: the job arrives as code, as a script's
    function did when the benchmarks ran as scripts."""
    cloudpickle = pytest.importorskip("ray.cloudpickle")
    import benchmarks

    benchmarks.send_by_value()
    try:
        payload = cloudpickle.dumps(robustness.env_options)
    finally:
        cloudpickle.unregister_pickle_by_value(benchmarks)
    code = ("import pickle, sys, types\n"
            "f = pickle.loads(sys.stdin.buffer.read())\n"
            # this repository's benchmarks, not the top-level benchmarks/ folder torchrl 0.11's wheel installs
            "try:\n    import benchmarks.robustness\nexcept ImportError:\n    pass\n"
            "else:\n    raise SystemExit('importable')\n"
            "print(f(types.SimpleNamespace(restitution=0.75), 'e', 0.1, 1))")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    done = subprocess.run([sys.executable, "-c", code], input=payload, cwd=tmp_path, env=env, capture_output=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr.decode()
    assert done.stdout.decode().strip() == "{'restitution': 0.85}"


def test_no_sys_path_edits_in_benchmarks_and_tests():
    hits = []
    for folder in ("benchmarks", "tests"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                if (isinstance(node, ast.Attribute) and node.attr == "path" and isinstance(node.value, ast.Name)
                        and node.value.id == "sys"):
                    hits.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    assert hits == []



def _planner_cache(path: Path, rows: dict[bool, str]) -> None:
    keys = {baseline: json.dumps(["corridor", "sr", "highs", baseline, 1, 5.0]) for baseline in rows}
    path.write_text("".join(json.dumps({"key": keys[b], "row": r}) + "\n" for b, r in rows.items()))


def test_planner_benchmark_resumes_from_its_cells(tmp_path, capsys):
    """``--cache`` is a CellStore: the rows done are printed from it, not solved again (issue 24: the cache was
    appended in place, and a kill mid-write left a line that blocked the next run)."""
    from benchmarks import planner

    cache = tmp_path / "planner.jsonl"
    _planner_cache(cache, {False: "| corridor | highs | cached row |", True: "| corridor | highs | cached baseline |"})
    before = cache.read_bytes()
    planner.main(["--planners", "sr", "--scenarios", "corridor", "--solvers", "highs", "--repeats", "1",
                  "--time-limit", "5", "--cache", str(cache)])
    out = capsys.readouterr().out
    assert "| corridor | highs | cached row |" in out and "| corridor | highs | cached baseline |" in out
    assert cache.read_bytes() == before  # nothing solved, nothing rewritten


def test_planner_benchmark_names_a_cut_line(tmp_path):
    from benchmarks import planner
    from impact_env.errors import ResultsFileError

    cache = tmp_path / "planner.jsonl"
    _planner_cache(cache, {False: "| corridor | highs | cached row |"})
    with cache.open("a") as f:
        f.write('{"key": "[\\"corridor\\", \\"sr\\"')  # what a kill during an in-place append left
    with pytest.raises(ResultsFileError, match="line 2 .*not a complete JSON object.*sed -i '2d'"):
        planner.main(["--planners", "sr", "--scenarios", "corridor", "--solvers", "highs", "--repeats", "1",
                      "--time-limit", "5", "--cache", str(cache)])


def test_handover_agreement_names_an_unknown_scenario(capsys):
    from benchmarks import handover_agreement

    with pytest.raises(SystemExit) as info:
        handover_agreement.main(["--scenarios", "two_objects,no_such_task"])
    assert info.value.code == 2 and "--scenarios: no plan in" in capsys.readouterr().err


def test_handover_agreement_table_counts_the_episodes_that_differ():
    from benchmarks.handover_agreement import table

    def cell(tree, rhos):
        return {"tree": tree, "cell": "relay e 0.3", "result": [
            {"seed": k, "success": r > 0, "robustness": r, "statuses": ["accepted"]} for k, r in enumerate(rhos)]}

    text = table([cell("this checkout", [0.2, -0.1]), cell("old", [0.2, 0.3])], "old", ["relay"])
    assert "| relay e 0.3 | this checkout | 1/2 | +0.050 | -0.100 | 2 | 0 | 1 |" in text
    assert "| relay e 0.3 | old | 2/2 | +0.250 | +0.200 | 2 | 0 | 1 |" in text


def test_impact_robust_cells_of_an_earlier_plan_are_marked(tmp_path):
    """A cell flown at another delta than the cached IR plan's (the plan changed since) gets a dagger and the
    note; one at the plan's delta does not."""
    (tmp_path / "plans" / "ir").mkdir(parents=True)
    shutil.copy(DATA / "plans" / "ir" / "throw_and_catch_exp.json", tmp_path / "plans" / "ir")
    deltas = impact_robust.plan_deltas(tmp_path)
    delta = deltas["throw_and_catch_exp"]
    episodes = [{"seed": 0, "success": True, "robustness": 0.2, "final_speed": 0.01, "in_final_box": True,
                 "mission_replans": 0}]
    cells = [{"scenario": "throw_and_catch_exp", "planner": "ir", "stack": "paper", "axis": "noise", "level": d,
              "delta": d, "episodes": episodes, "config": impact_robust.config_fingerprint("paper")}
             for d in (delta, 0.06)]
    text = impact_robust.table(cells, ["throw_and_catch_exp"], deltas)
    assert f"| impact noise 1 delta ({delta:.4g} m/s) | paper | ir |" in text
    assert "| impact noise 1 delta (0.06 m/s) | paper † | ir |" in text
    assert text.endswith("not what today's plans do") and "flies it again" not in text
    assert "†" not in impact_robust.table(cells[:1], ["throw_and_catch_exp"], deltas)


def test_the_impact_robust_summary_counts_the_current_cells_only():
    """summary.md: successes per scenario, stack and plan at 1, 2, 5 x delta and over the restitution cells, of the
    cells flown with today's config, delta and plan; any other cell is left out ("-")."""
    today = impact_robust.config_fingerprint("all")

    def cell(axis, level, successes, config=today, delta=0.01, plan="p"):
        return {"scenario": "s", "planner": "ir", "stack": "all", "axis": axis, "level": level, "delta": delta,
                "config": config, "plan": plan, "episodes": [{"success": ok} for ok in successes]}

    cells = [cell("noise", 0.01, [True, True, False]), cell("noise", 0.02, [True], config="0" * 12),
             cell("noise", 0.05, [False], delta=0.02), cell("noise", 0.05, [True, False], plan="q"),
             cell("e", -0.2, [True]), cell("e", 0.2, [False])]
    text = impact_robust.summary(cells, ["s"], {"s": 0.01}, {("s", "ir"): "p"})
    assert "| s | 0.01 | all | ir | 2 / 3 | - | - | 1 / 2 |" in text.splitlines()
