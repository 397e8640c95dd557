"""The run folder every trainer shares: ``--out`` or ``<--runs-dir>/<name>``, checked the same way everywhere."""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

import pytest

from baselines.bc import BCConfig
from baselines.dagger import DAggerConfig
from baselines.run_folder import check_run_folder, run_folder_path
from baselines.train import TrainConfig
from impact_env.cli_options import add_run_folder
from impact_env.errors import ImpactEnvError


def test_out_wins_over_the_default_name():
    assert run_folder_path("here/run", "runs", "bc_corridor_s0") == Path("here/run")
    assert run_folder_path(None, "runs", "bc_corridor_s0") == Path("runs/bc_corridor_s0")
    assert run_folder_path("", "elsewhere", "x") == Path("elsewhere/x")


@dataclass
class _Config:
    out: object = None
    runs_dir: object = "runs"


@pytest.mark.parametrize("out, runs_dir, field", [(3, "runs", "out"), (None, "", "runs_dir"), (None, None, "runs_dir")])
def test_bad_folders_are_typed_errors_naming_the_field(out, runs_dir, field):
    with pytest.raises(ImpactEnvError, match=field):
        check_run_folder(_Config(out, runs_dir), "bc_<scenario>_s<seed>")


@pytest.mark.parametrize("config", [BCConfig, DAggerConfig])
def test_trainer_configs_check_their_run_folder(config):
    with pytest.raises(ImpactEnvError, match="runs_dir"):
        config("corridor", runs_dir="")


def test_train_config_checks_its_run_folder():
    with pytest.raises(ImpactEnvError, match="runs_dir"):
        TrainConfig("ppo", "corridor", runs_dir="")


def test_cli_options_of_a_run_folder():
    p = argparse.ArgumentParser()
    add_run_folder(p, "model.zip", "x_<scenario>_s<seed>", resume="continue it")
    args = p.parse_args(["--runs-dir", "mine", "--resume"])
    assert (args.out, args.runs_dir, args.resume) == (None, "mine", True)
    assert "<--runs-dir>/x_<scenario>_s<seed>" in p.format_help()
    without = argparse.ArgumentParser()
    add_run_folder(without, "model.zip", "y")
    assert not hasattr(without.parse_args([]), "resume")
    with pytest.raises(SystemExit):
        without.parse_args(["--runs-dir", " "])
