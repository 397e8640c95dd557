"""DAgger (baselines/dagger.py, baselines/dagger_label.py) on throw_and_catch_exp (200 steps an episode): the
expert's labels of a learner-visited episode, the aggregation of the rounds, the resume, the CLI, the config."""

from __future__ import annotations

import json

import numpy as np
import pytest

from impact_env.cli import main
from impact_env.errors import ImpactEnvError
from tests.optional import requires
from tests.shipped_plans import path as committed_plan

pytestmark = requires("stable_baselines3")
SCENARIO = "throw_and_catch_exp"
NOISE = {"thrust_noise": 0.05, "initial_position_noise_m": 0.05}
# seconds, which vary between runs
TIMING = {"label_s", "replan_label_s", "label_ms_median", "fit_s", "eval_s", "wall_s", "eval_ms_per_step"}


def _expert():
    from planners.expert import Expert
    from planners.plan import Plan

    return Expert(SCENARIO, plan=Plan.load(committed_plan("sr", SCENARIO)))


def _env():
    from impact_env.transport.gym_env import TransportEnv

    return TransportEnv(SCENARIO, **NOISE)


def test_the_label_of_a_learner_visited_state_is_what_the_expert_outputs_there():
    """A random learner flies half the steps; replaying its executed actions reproduces the world it made, and a
    fresh expert fed those observations and contact reports in order gives exactly the recorded labels, which
    differ from the actions of the expert's own episode of the same seed (the states are the learner's)."""
    from baselines.dagger_label import labelled_episode
    from impact_env.controllers import RandomController

    episode = labelled_episode(_env(), _expert(), seed=5, learner=RandomController(), beta=0.5,
                               rng=np.random.default_rng(0))
    assert episode.steps == 200 and 0.35 < episode.expert_acted.mean() < 0.65
    executed = np.where(episode.expert_acted[:, None], episode.labels, episode.learner_actions)
    env, expert = _env(), _expert()
    obs, info = env.reset(seed=5)
    expert.reset()
    for t in range(episode.steps):
        np.testing.assert_array_equal(obs.astype(np.float32), episode.observations[t])
        np.testing.assert_array_equal(expert.act(obs, info), episode.labels[t])
        obs, _, _, _, info = env.step(executed[t])

    own = labelled_episode(_env(), _expert(), seed=5)  # the expert alone: its labels are its actions
    assert own.expert_acted.all() and np.isnan(own.learner_actions).all()
    assert not np.allclose(own.observations[-1], episode.observations[-1], atol=1e-3)
    assert np.abs(own.labels - episode.labels).max() > 0.1


def test_a_label_that_needs_a_re_plan_is_counted_and_timed():
    """Random thrust all episode long takes the object off the plan: the expert's mission layer re-plans from
    the learner's states, every MILP call is one label that needed it, and the episode records the cap."""
    from baselines.dagger_label import labelled_episode
    from impact_env.controllers import RandomController

    expert = _expert()
    episode = labelled_episode(_env(), expert, seed=3, learner=RandomController(), beta=0.0,
                               rng=np.random.default_rng(0))
    records = expert.mission.records
    assert not episode.expert_acted.any() and len(records) >= 1
    assert episode.replan_attempts == len(records) == int(episode.replan_labels.sum())
    assert episode.replans_accepted == sum(r.status.startswith("accepted") for r in records)
    assert episode.replan_cap_reached == (len(records) >= expert.mission.config.max_replans)
    # the labels that re-planned are at the times of the records (one control period after the step began)
    times = np.flatnonzero(episode.replan_labels) * 0.1
    np.testing.assert_allclose(times, [r.time_s for r in records], atol=1e-9)
    assert (episode.label_s > 0).all()
    assert labelled_episode(_env(), expert, seed=3).replan_attempts == 0  # the expert alone flies its plan


def _config(**overrides):
    from baselines.dagger import DAggerConfig

    return DAggerConfig(**{"scenario": SCENARIO, "rounds": 2, "initial_episodes": 2, "episodes_per_round": 2,
                           "eval_episodes": 1, "epochs": 2, "plan": str(committed_plan("sr", SCENARIO)),
                           "env_options": NOISE, "quiet": True, **overrides})


def _rows(run) -> list[dict]:
    return [{k: v for k, v in row.items() if k not in TIMING}
            for row in json.loads((run / "dagger.json").read_text())["rounds"]]


@pytest.fixture(scope="module")
def full_run(tmp_path_factory):
    """Two DAgger rounds through the CLI, and the learner flown by `impact-env run`."""
    out = tmp_path_factory.mktemp("dagger") / "full"
    assert main(["dagger", SCENARIO, "--rounds", "2", "--initial-episodes", "2", "--episodes-per-round", "2",
                 "--eval-episodes", "1", "--epochs", "2", "--plan", str(committed_plan("sr", SCENARIO)),
                 "--thrust-noise", "0.05", "--initial-position-noise-m", "0.05", "--out", str(out), "--quiet"]) == 0
    return out


def test_rounds_aggregate_the_labelled_episodes(full_run, tmp_path):
    from baselines.dagger import episode_seed, load_round

    rows = _rows(full_run)
    assert [r["round"] for r in rows] == [0, 1, 2] and [r["beta"] for r in rows] == [1.0, 0.5, 0.25]
    assert [r["dataset_episodes"] for r in rows] == [2, 4, 6]
    assert [r["dataset_labels"] for r in rows] == [r["env_steps"] for r in rows] == [400, 800, 1200]
    assert rows[0]["expert_acted_share"] == 1.0 and rows[0]["learner_label_mse"] is None
    assert all(0 < r["expert_acted_share"] < 1 and r["learner_label_mse"] > 0 for r in rows[1:])
    assert all(r["val_mse"] > 0 and r["eval_success"] in (0.0, 1.0) for r in rows)
    rounds = [load_round(full_run, k) for k in range(3)]
    assert [[e.seed for e in r] for r in rounds] == [[episode_seed(0, k, j) for j in range(2)] for k in range(3)]
    assert all(r["replan_labels"] == sum(int(e.replan_labels.sum()) for e in eps) for r, eps in zip(rows, rounds))
    meta = json.loads((full_run / "train.json").read_text())
    # the last fit saw every labelled episode but round 0's held-out one: 5 episodes, 1,000 labels
    assert meta["method"] == "DAgger" and meta["round"] == 2 and meta["samples"] == 1000
    assert meta["episodes_train"] == 5 and meta["episodes_validation"] == 1 and meta["env_options"] == NOISE
    summary = tmp_path / "run.json"
    assert main(["run", SCENARIO, "--controller", str(full_run / "model.zip"), "--thrust-noise", "0.05",
                 "--initial-position-noise-m", "0.05", "--json", str(summary)]) == 0
    assert isinstance(json.loads(summary.read_text())["robustness"], float)


def test_a_stopped_run_resumes_to_the_same_rounds(full_run, tmp_path):
    from baselines.dagger import dagger, load_round

    out = tmp_path / "resumed"
    dagger(_config(rounds=1, out=str(out)))
    assert len(_rows(out)) == 2
    with pytest.raises(ImpactEnvError, match="--resume"):
        dagger(_config(out=str(out)))
    with pytest.raises(ImpactEnvError, match="beta_decay 0.5, now 0.3"):
        dagger(_config(out=str(out), resume=True, beta_decay=0.3))
    dagger(_config(out=str(out), resume=True))
    assert _rows(out) == _rows(full_run)
    for k in range(3):
        for a, b in zip(load_round(out, k), load_round(full_run, k)):
            np.testing.assert_array_equal(a.observations, b.observations)
            np.testing.assert_array_equal(a.labels, b.labels)
    assert (out / "model.zip").read_bytes() != b"" and json.loads((out / "train.json").read_text())["round"] == 2


def test_a_run_returns_its_best_round_on_its_own_validation_episodes(tmp_path):
    """With ``select_episodes`` every round's policy flies validation episodes of its own (seeds apart from the
    training and evaluation ones), and the run folder's policy is the round that did best on them; each round's
    policy stays in rounds/policy_NNN/, and the next round's learner was its round's."""
    from baselines.dagger import SELECT_SEED0, dagger, selected_round

    out = tmp_path / "selected"
    dagger(_config(out=str(out), select_episodes=2))
    state = json.loads((out / "dagger.json").read_text())
    rows = state["rounds"]
    assert all(r["select_successes"] in (0, 1, 2) and isinstance(r["select_robustness_m"], float) for r in rows)
    chosen = state["selected_round"]
    assert chosen == selected_round(rows)
    assert (out / "model.zip").read_bytes() == (out / "rounds" / f"policy_{chosen:03d}" / "model.zip").read_bytes()
    assert json.loads((out / "train.json").read_text())["round"] == chosen
    assert all((out / "rounds" / f"policy_{k:03d}" / "vecnormalize.json").is_file() for k in range(3))
    assert SELECT_SEED0 > 10**9 + 10**6  # past every evaluation seed a run can use


def test_the_selected_round_is_the_most_successes_then_robustness_then_the_later_round():
    from baselines.dagger import selected_round

    def row(k, wins, rho):
        return {"round": k, "select_successes": wins, "select_robustness_m": rho}

    assert selected_round([row(0, 1, 0.1), row(1, 3, -0.2), row(2, 2, 0.5)]) == 1
    assert selected_round([row(0, 3, 0.1), row(1, 3, 0.2), row(2, 1, 0.5)]) == 1
    assert selected_round([row(0, 3, 0.2), row(1, 3, 0.2)]) == 1
    assert selected_round([{"round": 0}, {"round": 1}]) == 1  # not validated: the last round


@pytest.mark.parametrize(("field", "value", "message"), [
    ("rounds", -1, "rounds"), ("episodes_per_round", 0, "episodes_per_round"), ("beta_decay", 1.5, "beta_decay"),
    ("seed", 1000, "seed"), ("net_arch", (), "net_arch"), ("env_options", "noisy", "env_options"),
    ("epochs", 0, "epochs"), ("learning_rate", 0.0, "learning_rate"), ("max_replans", -1, "max_replans"),
    ("resume", "yes", "resume"), ("scenario", "", "scenario"), ("select_episodes", -1, "select_episodes")])
def test_a_bad_config_is_a_typed_error_naming_the_field(field, value, message):
    from baselines.dagger import DAggerConfig

    with pytest.raises(ImpactEnvError, match=f"DAggerConfig.{message}"):
        DAggerConfig(**{"scenario": SCENARIO, field: value})


def test_round_zero_can_be_a_recorded_dataset(tmp_path):
    """`impact-env record`'s episodes are round 0 (the expert's actions as labels, nothing timed); round 1 then
    labels the learner's episodes as usual."""
    pytest.importorskip("minari")
    from baselines.dagger import dagger, load_round

    datasets = tmp_path / "datasets"
    assert main(["record", SCENARIO, "--episodes", "2", "--out", str(datasets), "--plan",
                 str(committed_plan("sr", SCENARIO)), "--thrust-noise", "0.05", "--initial-position-noise-m", "0.05",
                 "--quiet"]) == 0
    run = dagger(_config(rounds=1, dataset_dir=str(datasets), out=str(tmp_path / "run")))
    rows = json.loads((run / "dagger.json").read_text())["rounds"]
    assert [r["dataset_episodes"] for r in rows] == [2, 4] and rows[0]["label_s"] is None
    assert rows[1]["label_s"] > 0 and rows[1]["expert_acted_share"] < 1
    recorded = load_round(run, 0)
    assert [e.steps for e in recorded] == [200, 200] and recorded[0].expert_acted.all()
