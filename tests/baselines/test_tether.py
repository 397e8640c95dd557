"""The learned-baseline tools on a tether station: PPO trains, flies, and meets the expert in one bench."""

from __future__ import annotations

import csv
import json

from baselines import hyperparams
from baselines.train import env_id_for
from impact_env import TETHER_GYM_IDS, TETHER_GYM_IDS_V0
from impact_env.cli import main
from tests.optional import requires

pytestmark = requires("stable_baselines3")  # looked up, not imported: the tests import it when they run


def test_every_tether_env_id_has_ppo_hyperparameters():
    for env_id in [*TETHER_GYM_IDS, *TETHER_GYM_IDS_V0]:
        entry = hyperparams.load("ppo", env_id)
        assert entry["n_timesteps"] > 0 and isinstance(entry["policy_kwargs"], dict)
    assert env_id_for("dead_end") == "impact_env/TetherDeadEnd-v1"  # the current version's id


def test_ppo_on_a_station_then_expert_versus_ppo_in_one_bench(tmp_path, capsys):
    runs = tmp_path / "runs"
    assert main(["train", "ppo", "dead_end", "--timesteps", "512", "--n-envs", "1", "--runs-dir", str(runs),
                 "--no-progress", "--eval-freq", "100000", "--fidelity", "reel"]) == 0
    model = runs / "ppo_dead_end_s0" / "model.zip"
    meta = json.loads((runs / "ppo_dead_end_s0" / "train.json").read_text())
    assert model.is_file() and meta["env_id"] == "impact_env/TetherDeadEnd-v1"  # training uses the current id
    assert meta["env_options"]["fidelity"] == "reel"
    out = tmp_path / "bench"
    assert main(["bench", "dead_end", "--controllers", f"expert,ppo:{model},zero", "--episodes", "1",
                 "--workers", "1", "--out", str(out), "--fidelity", "reel", "--initial-position-noise-m", "0.3"]) == 0
    rows = {r["controller"]: r for r in csv.DictReader(open(out / "summary.csv"))}
    assert float(rows["expert"]["success_rate"]) == 1.0 and float(rows["zero"]["success_rate"]) == 0.0
    assert "ppo" in rows and (out / "bench.png").stat().st_size > 1000
    assert main(["run", "dead_end", "--controller", str(model), "--episodes", "1"]) == 0


def test_impact_options_on_a_station_are_errors(tmp_path, capsys):
    assert main(["train", "ppo", "L", "--thrust-noise", "0.1", "--out", str(tmp_path)]) == 2
    assert "applies to impact scenarios" in capsys.readouterr().err
    assert main(["train", "sac", "L", "--out", str(tmp_path)]) == 2
    assert "ppo" in capsys.readouterr().err
