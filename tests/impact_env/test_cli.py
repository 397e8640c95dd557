"""The impact-env command: list, show, run (JSON summary, video, plot) and its error messages."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from impact_env.cli import main
from tests.helpers import one_line_error


def test_scenarios_lists_the_shipped_ones(capsys):
    assert main(["scenarios"]) == 0
    out = capsys.readouterr().out
    for name in ("corridor", "obstacle_avoidance", "throw_and_catch_exp"):
        assert name in out


def test_show_writes_a_png(tmp_path):
    out = tmp_path / "setup.png"
    assert main(["show", "obstacle_avoidance", "--out", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_run_writes_summary_video_and_plot(tmp_path):
    paths = {k: tmp_path / f"r.{k}" for k in ("json", "mp4", "png")}
    code = main(["run", "throw_and_catch_exp", "--controller", "random", "--seed", "3", "--episodes", "2",
                 "--json", str(paths["json"]), "--video", str(paths["mp4"]), "--plot", str(paths["png"])])
    assert code == 0
    summary = json.loads(paths["json"].read_text())
    assert summary["scenario"] == "throw_and_catch_exp" and summary["controller"] == "random"
    assert isinstance(summary["success"], bool) and isinstance(summary["robustness"], float)
    assert isinstance(summary["fuel_Ns"], float) and summary["fuel_Ns"] > 0
    assert [e["seed"] for e in summary["episodes"]] == [3, 4]
    for impact in summary["impacts"]:
        assert {"time", "a", "b", "impulse"} <= set(impact)
    assert paths["mp4"].stat().st_size > 1000 and paths["png"].stat().st_size > 1000


def test_run_zero_controller_on_a_user_file(tmp_path):
    from importlib.resources import files

    text = files("impact_env.transport.scenarios").joinpath("throw_and_catch_exp.toml").read_text()
    path = tmp_path / "lab.toml"
    path.write_text(text)
    out = tmp_path / "zero.json"
    assert main(["run", str(path), "--controller", "zero", "--json", str(out)]) == 0
    summary = json.loads(out.read_text())
    assert summary["success"] is False and summary["impacts"] == [] and summary["fuel_Ns"] == 0.0
    assert summary["robustness"] == pytest.approx(-0.6, abs=1e-6)


@pytest.mark.parametrize("argv,message", [
    (["run", "nowhere"], "unknown scenario 'nowhere'"),
    (["run", "corridor", "--controller", "magic"], "unknown controller 'magic'"),
    (["run", "corridor", "--episodes", "0"], "--episodes must be >= 1"),
    (["run", "corridor", "--restitution", "3"], "restitution must be in [0, 1]"),
    # each world family refuses the other's options
    (["run", "L", "--restitution", "0.5"], "--restitution applies to impact scenarios, not to station 'L'"),
    (["run", "corridor", "--fidelity", "reel"], "--fidelity applies to tether stations, not to impact scenarios"),
    (["run", "L", "--reward-mode", "conjuncts"], "--reward-mode conjuncts applies to impact scenarios"),
])
def test_errors_are_one_line_messages(argv, message, capsys):
    assert message in one_line_error(argv, capsys)


def test_console_script_is_installed():
    result = subprocess.run([sys.executable, "-m", "impact_env.cli", "scenarios"], capture_output=True, text=True)
    assert result.returncode == 0 and "corridor" in result.stdout


def test_cli_starts_without_the_rl_extra():
    """`make demo` installs only the base package: building the CLI (which loads every subcommand plug-in)
    must not import stable-baselines3, yaml, minari or torch."""
    code = (
        "import sys, importlib.abc\n"
        "class Block(importlib.abc.MetaPathFinder):\n"
        "    def find_spec(self, name, path, target=None):\n"
        "        if name.split('.')[0] in {'yaml', 'stable_baselines3', 'minari', 'torch', 'supersuit'}:\n"
        "            raise ImportError('blocked ' + name)\n"
        "sys.meta_path.insert(0, Block())\n"
        "from impact_env.cli import build_parser\n"
        "build_parser().parse_args(['scenarios'])\n"
        "print('ok')\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert result.returncode == 0 and "ok" in result.stdout, result.stderr
