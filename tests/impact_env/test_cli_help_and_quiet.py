"""The command line as a new user meets it: clean help with defaults, "did you mean", --version, quiet headless
rendering and quiet solver banners in spawned workers, figures with the same numbers as the CLI."""

from __future__ import annotations

import argparse
import os
import subprocess
import sys

import pytest

from impact_env.cli import build_parser, main
from tests.helpers import one_line_error


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    return next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices


def test_version(capsys):
    import impact_env

    with pytest.raises(SystemExit) as stop:
        main(["--version"])
    assert stop.value.code == 0
    assert capsys.readouterr().out.strip() == f"impact-env {impact_env.__version__}"


def test_main_help_is_clean_text(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    out = capsys.readouterr().out
    assert "``" not in out and ":class:" not in out and ":mod:" not in out
    assert "examples:" in out and "impact-env plan corridor" in out


@pytest.mark.parametrize("command", ["scenarios", "show", "run", "train", "bench", "record", "bc", "dagger", "bc-rl",
                                     "residual", "curves", "plan"])
def test_every_option_has_help_and_shows_its_default(command):
    parser = _subparsers(build_parser())[command]
    text = parser.format_help()
    assert "``" not in text and "see impact_env" not in text
    for action in parser._actions:
        if isinstance(action, argparse._HelpAction):
            continue
        assert action.help, f"impact-env {command} {action.option_strings or action.dest} has no help"
        shown = action.default not in (None, False) and action.option_strings
        if shown:
            help_text = parser._get_formatter()._expand_help(action)
            assert "default" in help_text, (command, action.option_strings, help_text)


def test_run_help_names_the_model_path_form_and_the_reward_modes():
    text = _subparsers(build_parser())["run"].format_help()
    assert "model.zip" in text
    for mode in ("dense", "sparse", "conjuncts"):
        assert f"{mode}:" in text


@pytest.mark.parametrize("argv, hint", [
    (["trian", "ppo", "corridor"], "did you mean 'train'?"),
    (["run", "corridor", "--reward-mode", "dens"], "did you mean 'dense'?"),
    (["run", "corridor", "--controler", "x"], "did you mean '--controller'?"),
])
def test_argparse_errors_suggest_a_name(argv, hint, capsys):
    with pytest.raises(SystemExit) as stop:
        main(argv)
    assert stop.value.code == 2 and hint in capsys.readouterr().err


@pytest.mark.parametrize("argv, hint", [
    (["run", "coridor"], "did you mean 'corridor'?"),
    (["run", "alcov"], "did you mean 'alcove'?"),
    (["run", "corridor", "--controller", "exprt"], "did you mean 'expert'?"),
    (["plan", "corridor", "--solver", "higs"], "did you mean 'highs'?"),
])
def test_names_get_a_suggestion(argv, hint, capsys):
    assert hint in one_line_error(argv, capsys)


def _headless_env() -> dict[str, str]:
    drop = {"XDG_RUNTIME_DIR", "DISPLAY", "WAYLAND_DISPLAY", "SDL_VIDEODRIVER", "SDL_AUDIODRIVER"}
    return {k: v for k, v in os.environ.items() if k not in drop}


def test_headless_rendering_is_quiet(tmp_path):
    code = ("import impact_env, gymnasium as gym\n"
            "for mode in ('rgb_array', 'human'):\n"
            "    for env_id in ('impact_env/ThrowAndCatchExp-v0', 'impact_env/TetherL-v0'):\n"
            "        env = gym.make(env_id, render_mode=mode)\n"
            "        env.reset(seed=0); env.step(env.action_space.sample()); env.render(); env.close()\n"
            "print('ok')\n")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=_headless_env(),
                            cwd=tmp_path, timeout=300)
    assert result.returncode == 0 and "ok" in result.stdout, result.stderr
    assert "XDG_RUNTIME_DIR" not in result.stderr and "ALSA" not in result.stderr, result.stderr
    video = subprocess.run([sys.executable, "-m", "impact_env.cli", "run", "throw_and_catch_exp", "--controller",
                            "random", "--video", str(tmp_path / "v.mp4")], capture_output=True, text=True,
                           env=_headless_env(), cwd=tmp_path, timeout=300)
    assert video.returncode == 0 and "XDG_RUNTIME_DIR" not in video.stderr + video.stdout, video.stderr


def test_spawned_bench_workers_print_no_solver_banner(tmp_path):
    result = subprocess.run([sys.executable, "-m", "impact_env.cli", "bench", "throw_and_catch_exp", "--controllers",
                             "expert", "--episodes", "1", "--workers", "1", "--out", str(tmp_path / "b")],
                            capture_output=True, text=True, cwd=tmp_path, timeout=900)
    assert result.returncode == 0, result.stderr
    text = result.stdout + result.stderr
    assert "HiGHS" not in text and "Running" not in text, text


def test_run_line_and_plot_title_count_impacts_alike(tmp_path, capsys):
    from matplotlib.image import imread

    png = tmp_path / "run.png"
    assert main(["run", "throw_and_catch_exp", "--controller", "random", "--seed", "1", "--plot", str(png)]) == 0
    line = capsys.readouterr().out.splitlines()[0]
    assert "robot-object;" in line and "contacts in all" in line
    assert imread(png).shape[1] > 1000  # three panels: xy, positions, velocities
