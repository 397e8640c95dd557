"""One option vocabulary on every command, checked output paths, atomic writes (issue 24).

- ``--out DIR`` is a folder on every command that has it; ``--json PATH``, ``--plot PNG``, ``--video MP4`` are
  single files; ``--seed`` and the noise options wherever episodes run; ``--quiet`` on every long command;
- argparse's prefix matching is off (``--timestep 10`` was ``--timesteps 10``);
- the 0.2 spellings still work for one release, with a deprecation message;
- every output path is checked before any episode, plan or training step, and an unwritable one is an
  ``OutputPathError`` naming it (10 of 14 such cases lost finished work in 0.2; ``show --out /dev/full`` wrote
  ``/dev/full.png`` and reported success);
- a controller typo is reported before any episode or plan.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pytest

from impact_env.cli import build_parser, main
from impact_env.errors import OutputPathError
from tests.helpers import one_line_error

LONG_COMMANDS = ("run", "plan", "train", "bench", "record", "bc", "dagger", "bc-rl", "residual", "dataset", "filter")
EPISODE_COMMANDS = ("run", "bench", "record", "train", "dataset", "dagger", "bc-rl", "residual")
NOISE = ("--thrust-noise", "--initial-position-noise-m", "--impact-velocity-noise-mps", "--restitution",
         "--fuel-penalty", "--reward-mode")
STATION = ("--fidelity", "--energy-penalty", "--pull-speed-mps", "--max-active")


def _subparsers() -> dict[str, argparse.ArgumentParser]:
    parser = build_parser()
    return next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices


def _options(command: str) -> dict[str, argparse.Action]:
    return {o: a for a in _subparsers()[command]._actions for o in a.option_strings}


# ------------------------------------------------------------------------------------------ the vocabulary


def test_out_is_a_folder_everywhere_and_files_have_their_own_options():
    seen = set()
    for command in _subparsers():
        options = _options(command)
        if "--out" in options:
            seen.add(command)
            assert options["--out"].metavar == "DIR", command
            assert "folder" in options["--out"].help, command
        for flag, metavar in (("--json", "PATH"), ("--plot", "PNG"), ("--video", "MP4")):
            if flag in options:
                assert options[flag].metavar == metavar, (command, flag)
    assert seen >= {"show", "run", "plan", "train", "bench", "record", "bc", "curves", "generate", "dataset",
                    "filter"}


@pytest.mark.parametrize("command", LONG_COMMANDS)
def test_every_long_command_has_quiet(command):
    assert _options(command)["--quiet"].default is False


@pytest.mark.parametrize("command", EPISODE_COMMANDS)
def test_seed_and_noise_wherever_episodes_run(command):
    options = _options(command)
    assert "--seed" in options
    assert set(NOISE) <= set(options), set(NOISE) - set(options)


@pytest.mark.parametrize("command", ["run", "train", "bench"])
def test_station_options_wherever_stations_fly(command):
    assert set(STATION) <= set(_options(command))


def test_prefix_matching_is_off(capsys):
    for parser in (build_parser(), *_subparsers().values()):
        assert parser.allow_abbrev is False
    with pytest.raises(SystemExit):
        build_parser().parse_args(["train", "ppo", "corridor", "--timestep", "10"])
    err = capsys.readouterr().err
    assert "unrecognized arguments: --timestep 10" in err and "did you mean '--timesteps'?" in err
    with pytest.raises(SystemExit):
        build_parser().parse_args(["run", "corridor", "--epi", "3"])


# ------------------------------------------------------------------------------------------- old spellings


def test_show_out_file_is_the_old_plot(tmp_path, capsys):
    assert main(["show", "corridor", "--out", str(tmp_path / "setup.png")]) == 0
    assert (tmp_path / "setup.png").stat().st_size > 1000
    err = capsys.readouterr().err
    assert "--out" in err and "is deprecated and goes in 0.4.0: use --plot" in err


def test_show_out_folder_and_plot(tmp_path, capsys):
    assert main(["show", "corridor", "--out", str(tmp_path / "figs")]) == 0
    assert (tmp_path / "figs" / "corridor.png").is_file()
    assert main(["show", "L", "--plot", str(tmp_path / "station")]) == 0
    assert (tmp_path / "station.png").is_file()
    assert "deprecated" not in capsys.readouterr().err


def test_plan_out_json_is_the_old_json(tmp_path, capsys):
    assert main(["plan", "throw_and_catch_exp", "--out", str(tmp_path / "plan.json"), "--quiet"]) == 0
    assert json.loads((tmp_path / "plan.json").read_text())["scenario"] == "throw_and_catch_exp"
    assert "use --json" in capsys.readouterr().err


def test_plan_out_folder_holds_plan_and_figure(tmp_path):
    assert main(["plan", "throw_and_catch_exp", "--out", str(tmp_path / "plans"), "--quiet"]) == 0
    assert {p.name for p in (tmp_path / "plans").iterdir()} == {"throw_and_catch_exp.json",
                                                                "throw_and_catch_exp.png"}


def test_plan_list_rejects_json_and_deprecates_plot_folder(tmp_path, capsys, monkeypatch):
    import planners.offline.batch

    err = one_line_error(["plan", "corridor,throw_and_catch_exp", "--json", str(tmp_path / "p.json")], capsys)
    assert "give --out DIR, not --json" in err
    monkeypatch.setattr(planners.offline.batch, "plan_scenarios", lambda names, config, engine: [])
    assert main(["plan", "corridor,throw_and_catch_exp", "--plot", str(tmp_path / "figs"), "--workers", "1"]) == 0
    assert "--plot" in capsys.readouterr().err and (tmp_path / "figs").is_dir()


def test_train_no_progress_is_the_old_quiet(capsys):
    args = build_parser().parse_args(["train", "ppo", "corridor", "--no-progress"])
    assert args.quiet is True
    assert "--no-progress is deprecated and goes in 0.4.0: use --quiet" in capsys.readouterr().err
    assert build_parser().parse_args(["train", "ppo", "corridor"]).quiet is False
    assert "--no-progress" not in _subparsers()["train"].format_help()  # hidden: the help shows the new name


def _run_folder(tmp_path: Path) -> Path:
    """A run folder with two evaluations, as ``impact-env train`` writes them."""
    import numpy as np

    run = tmp_path / "run"
    (run / "eval").mkdir(parents=True)
    np.savez(run / "eval" / "evaluations.npz", timesteps=np.array([100, 200]), results=np.array([[-0.5], [0.2]]))
    (run / "train.json").write_text(json.dumps({"algo": "ppo", "scenario": "corridor"}))
    return run


def test_curves_out_file_is_the_old_plot_and_out_is_a_folder(tmp_path, capsys):
    run = _run_folder(tmp_path)
    assert main(["curves", str(run), "--out", str(tmp_path / "old.png")]) == 0
    assert (tmp_path / "old.png").stat().st_size > 1000 and "use --plot" in capsys.readouterr().err
    assert main(["curves", str(run), "--out", str(tmp_path / "figs"), "--table", str(tmp_path / "t.md")]) == 0
    assert (tmp_path / "figs" / "curves.png").is_file() and "| ppo (dense) |" in (tmp_path / "t.md").read_text()


# ------------------------------------------------------------------------------------ checked before work


BAD_FILES = [("/dev/full", "is a character device, not a file"),
             ("/proc/impact_env_out.json", "cannot create files in /proc"),
             ("{tmp}", "is a folder, not a file"),
             ("{tmp}/a_file/out.json", "a part of the path is a file, not a folder")]


def _bad(path: str, tmp_path: Path) -> str:
    (tmp_path / "a_file").write_text("x")
    return path.format(tmp=tmp_path)


@pytest.fixture
def no_episode(monkeypatch):
    """Fail the test if an episode, a plan or a training step starts."""
    import baselines.bench
    import impact_env.rollout
    import planners.offline.impact_robust
    import planners.offline.spatially_robust

    def started(*args, **kwargs):
        raise AssertionError("work started before the output paths were checked")

    for module, name in ((impact_env.rollout, "run_episodes"), (impact_env.rollout, "run_episode"),
                         (planners.offline.spatially_robust, "plan_spatially_robust"),
                         (planners.offline.impact_robust, "plan_impact_robust"),
                         (baselines.bench, "open_engine")):
        monkeypatch.setattr(module, name, started)


@pytest.mark.parametrize("bad, message", BAD_FILES)
@pytest.mark.parametrize("argv", [
    ["run", "corridor", "--json", "{bad}"],
    ["run", "corridor", "--plot", "{bad}"],
    ["run", "throw_and_catch_exp", "--controller", "expert", "--json", "{bad}"],
    ["plan", "corridor", "--json", "{bad}"],
    ["plan", "corridor", "--plot", "{bad}"],
    ["plan", "L", "--json", "{bad}"],
    ["show", "corridor", "--plot", "{bad}"],
    ["curves", "runs/none", "--table", "{bad}"],
    ["generate", "--family", "gaps", "--toml", "{bad}"],
], ids=lambda v: " ".join(v) if isinstance(v, list) else None)
def test_an_unwritable_file_is_refused_before_any_work(argv, bad, message, tmp_path, capsys, no_episode):
    path = _bad(bad, tmp_path)
    option = argv[argv.index("{bad}") - 1]
    err = one_line_error([path if a == "{bad}" else a for a in argv], capsys)
    assert f"{option} {path}" in err and message in err
    assert not Path("/dev/full.png").exists()


@pytest.mark.parametrize("argv", [
    ["show", "corridor", "--out", "{bad}"],
    ["run", "corridor", "--out", "{bad}"],
    ["plan", "corridor", "--out", "{bad}"],
    ["plan", "corridor,throw_and_catch_exp", "--out", "{bad}"],
    ["bench", "throw_and_catch_exp", "--controllers", "zero", "--out", "{bad}"],
    ["record", "throw_and_catch_exp", "--out", "{bad}"],
    ["generate", "--family", "gaps", "--count", "2", "--out", "{bad}"],
    ["filter", "--family", "gaps", "--seeds", "0:2", "--out", "{bad}"],
    ["dataset", "--family", "gaps", "--tasks", "tasks", "--out", "{bad}"],
])
@pytest.mark.parametrize("bad, message", [("/dev/full", "is a character device, not a folder"),
                                          ("{tmp}/a_file", "is a file, not a folder"),
                                          ("/proc/impact_env_out", "cannot create the folder")])
def test_an_unwritable_folder_is_refused_before_any_work(argv, bad, message, tmp_path, capsys, no_episode):
    path = _bad(bad, tmp_path)
    err = one_line_error([path if a == "{bad}" else a for a in argv], capsys)
    assert f"--out {path}" in err and message in err


def test_show_out_dev_full_does_not_report_success(capsys):
    try:
        err = one_line_error(["show", "corridor", "--out", "/dev/full"], capsys)
        assert "--out /dev/full is a character device, not a folder" in err
        err = one_line_error(["show", "corridor", "--plot", "/dev/full"], capsys)
        assert "--plot /dev/full is a character device, not a file" in err
        assert not Path("/dev/full.png").exists()
    finally:
        if Path("/dev/full.png").is_file():  # a regression: do not leave it behind
            Path("/dev/full.png").unlink()


def test_a_video_must_be_an_mp4(tmp_path, capsys, no_episode):
    err = one_line_error(["run", "corridor", "--video", str(tmp_path / "run.avi")], capsys)
    assert "must end in .mp4" in err


def test_train_and_bc_check_their_run_folder_before_training(tmp_path, capsys, monkeypatch):
    pytest.importorskip("stable_baselines3")
    import stable_baselines3.common.env_util as env_util

    monkeypatch.setattr(env_util, "make_vec_env", lambda *a, **k: (_ for _ in ()).throw(AssertionError("trained")))
    (tmp_path / "a_file").write_text("x")
    err = one_line_error(["train", "ppo", "corridor", "--out", str(tmp_path / "a_file"), "--timesteps", "64"], capsys)
    assert "--out" in err and "is a file, not a folder" in err
    err = one_line_error(["bc", "corridor", "--out", str(tmp_path / "a_file")], capsys)
    assert "is a file, not a folder" in err


def test_the_output_error_is_typed_and_an_os_error():
    from impact_env.errors import TYPED_ERRORS, ImpactEnvError

    assert OutputPathError in TYPED_ERRORS and issubclass(OutputPathError, (ImpactEnvError, OSError))


# ------------------------------------------------------------------------------------ controller names


@pytest.mark.parametrize("controllers", ["zero,rnadom", "expert,rnadom", "rnadom"])
def test_a_controller_typo_is_reported_before_any_episode_or_plan(controllers, tmp_path, capsys, no_episode):
    err = one_line_error(["bench", "corridor", "--controllers", controllers, "--episodes", "1",
                          "--out", str(tmp_path / "bench")], capsys)
    assert "unknown controller 'rnadom' (did you mean 'random'?)" in err
    assert not (tmp_path / "bench").exists()


# ------------------------------------------------------------------------------------ options reach the envs


def test_bench_takes_seed_and_the_new_noise_options(tmp_path):
    import csv

    out = tmp_path / "bench"
    assert main(["bench", "throw_and_catch_exp", "--controllers", "random", "--episodes", "2", "--seed", "5",
                 "--impact-velocity-noise-mps", "0.01", "--fuel-penalty", "0.1", "--workers", "1", "--quiet",
                 "--out", str(out)]) == 0
    rows = list(csv.DictReader(open(out / "episodes.csv")))
    assert [int(r["seed"]) for r in rows] == [5, 6]
    summary = (out / "summary.md").read_text()
    assert "impact_velocity_noise_mps=0.01" in summary and "fuel_penalty=0.1" in summary


def test_bench_refuses_options_of_the_other_world(tmp_path, capsys):
    err = one_line_error(["bench", "corridor", "--controllers", "zero", "--fidelity", "reel",
                          "--out", str(tmp_path / "b")], capsys)
    assert "--fidelity applies to tether stations" in err
    err = one_line_error(["bench", "L", "--controllers", "zero", "--thrust-noise", "0.1",
                          "--out", str(tmp_path / "b")], capsys)
    assert "--thrust-noise applies to impact scenarios" in err


def test_record_passes_every_environment_option(monkeypatch):
    import baselines.record

    seen = {}

    def fake(scenario, episodes, out, plan, options, seed, quiet):
        seen.update(options=options, seed=seed, quiet=quiet)
        raise SystemExit(0)

    monkeypatch.setattr(baselines.record, "record", fake)
    with pytest.raises(SystemExit):
        main(["record", "corridor", "--restitution", "0.6", "--impact-velocity-noise-mps", "0.02", "--seed", "3",
              "--quiet"])
    assert seen["options"]["restitution"] == 0.6 and seen["options"]["impact_velocity_noise_mps"] == 0.02
    assert seen["seed"] == 3 and seen["quiet"] is True


def test_train_passes_the_station_options(monkeypatch):
    import baselines.train

    seen = {}

    def fake(config):
        seen["config"] = config
        raise SystemExit(0)

    monkeypatch.setattr(baselines.train, "train", fake)
    with pytest.raises(SystemExit):
        main(["train", "ppo", "L", "--fidelity", "reel", "--energy-penalty", "0.01", "--max-active", "1",
              "--pull-speed-mps", "0.2", "--quiet"])
    config = seen["config"]
    assert config.env_options == {"fidelity": "reel", "reward_mode": "dense", "energy_penalty": 0.01,
                                  "pull_speed_mps": 0.2, "max_active": 1, "initial_position_noise_m": 0.0}
    assert config.progress_bar is False


def test_run_quiet_prints_no_episode_lines(tmp_path, capsys):
    assert main(["run", "throw_and_catch_exp", "--episodes", "2", "--quiet", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "episode" not in out.replace("episode.png", "") and "wrote" in out
    assert json.loads((tmp_path / "summary.json").read_text())["scenario"] == "throw_and_catch_exp"


def test_generate_speaks_the_vocabulary(tmp_path, capsys):
    """``--toml PATH`` one task, ``--out DIR`` a folder of them; the first spelling ``--out task.toml`` still
    works, with the deprecation message."""
    assert main(["generate", "--family", "gaps", "--seed", "3", "--toml", str(tmp_path / "one.toml")]) == 0
    assert main(["generate", "--family", "gaps", "--seed", "3", "--out", str(tmp_path / "many")]) == 0
    assert (tmp_path / "many" / "gaps_3.toml").read_text() == (tmp_path / "one.toml").read_text()
    assert main(["generate", "--family", "gaps", "--seed", "3", "--out", str(tmp_path / "old.toml")]) == 0
    assert "--out " in capsys.readouterr().err and (tmp_path / "old.toml").is_file()
    assert main(["generate", "--family", "gaps", "--count", "2", "--toml", str(tmp_path / "x.toml")]) == 2
    assert "--toml is one file; --count 2 writes a folder: give --out DIR" in capsys.readouterr().err
    assert main(["generate", "--family", "gaps", "--count", "2"]) == 2


def test_dataset_and_filter_take_the_shared_options():
    args = build_parser().parse_args(["dataset", "--family", "gaps", "--tasks", "t", "--seed", "4", "--quiet",
                                      "--impact-velocity-noise-mps", "0.01", "--restitution", "0.7"])
    assert (args.seed, args.quiet, args.impact_velocity_noise_mps, args.restitution) == (4, True, 0.01, 0.7)
    assert build_parser().parse_args(["filter", "--family", "gaps", "--out", "o", "--quiet"]).quiet is True
