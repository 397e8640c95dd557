"""Command-line options that used to be accepted though meaningless (issue 11), and ``plan --quiet``, which
must print nothing but the result (HiGHS logs a banner from the first call to a new instance)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from impact_env.cli import main


@pytest.mark.parametrize("option, value, message", [
    ("--time-limit", "nan", "--time-limit must be a finite number of seconds > 0, got nan"),
    ("--time-limit", "inf", "--time-limit must be a finite"),
    ("--time-limit", "0", "--time-limit must be a finite"),
    ("--degree", "20", r"--degree must be in 2..8 \(as planner.robot_degree in scenario files\), got 20"),
    ("--degree", "1", "--degree must be in 2..8"),
    ("--intervals", "100000", "--intervals must be in 2..1000"),
    ("--seed", "-1", "--seed must be in 0.."),
    ("--node-limit", "0", "--node-limit must be >= 1, got 0"),
])
def test_plan_rejects_meaningless_options(capsys, option, value, message):
    assert main(["plan", "throw_and_catch_exp", option, value]) == 2
    err = capsys.readouterr().err
    assert err.startswith("impact-env: error:")
    assert __import__("re").search(message, err), err


def test_run_rejects_a_negative_seed(capsys):
    assert main(["run", "corridor", "--seed", "-1"]) == 2
    assert "--seed must be >= 0" in capsys.readouterr().err


def test_plan_quiet_prints_only_the_result():
    """In a fresh process (the banner comes once per new HiGHS instance, the first time it is called)."""
    env = {**os.environ, "PYTHONWARNINGS": "ignore"}
    proc = subprocess.run([sys.executable, "-m", "impact_env.cli", "plan", "throw_and_catch_exp", "--quiet",
                           "--refine-nodes", "0"], capture_output=True, text=True, timeout=300, env=env)
    assert proc.returncode == 0, proc.stderr
    output = proc.stdout + proc.stderr
    assert "HiGHS" not in output and "Copyright" not in output, output
    lines = proc.stdout.splitlines()
    assert lines[0].startswith("robustness rho = 0.4000 m") and lines[1] == "2 impacts:"
    assert all(line.startswith("  I") for line in lines[2:]) and len(lines) == 4
