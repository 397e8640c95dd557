"""Goal-conditioned PPO on many generated tasks (baselines/batched/family_ppo.py) at tiny sizes: the config's
checks, a run that trains, checkpoints and resumes, and its policy flying a task it never saw through the
family env id (the padded layout), loaded without pickles."""

from __future__ import annotations

import json

import numpy as np
import pytest

from impact_env.errors import ImpactEnvError, ModelFileError
from tests.optional import requires

pytestmark = requires("stable_baselines3")
TINY = {"tasks": (1000, 1001), "envs_per_task": 2, "n_steps": 8, "batch_size": 16, "n_epochs": 1,
        "checkpoint_frames": 32, "hidden": (16, 16)}


@pytest.mark.parametrize("bad, match", [
    ({"family": "nope"}, "family"),
    ({"tasks": ()}, "tasks"),
    ({"tasks": (1, 1)}, "repeats"),
    ({"tasks": (-1,)}, "tasks"),
    ({"batch_size": 7}, "divisor"),
    ({"gamma": 0.0}, "gamma"),
])
def test_bad_settings_are_typed_errors(bad, match):
    from baselines.batched.family_ppo import FamilyPpoConfig

    kwargs = {"family": "throw_and_catch", **TINY, **bad}
    with pytest.raises(ImpactEnvError, match=match):
        FamilyPpoConfig(**kwargs)


def test_a_run_trains_resumes_and_its_policy_flies_an_unseen_task(tmp_path):
    import gymnasium as gym

    import impact_env  # noqa: F401  (registers the ids)
    from baselines.batched.family_ppo import FamilyPpoConfig, FamilyPpoPolicy, run
    from impact_env.rollout import run_episode

    out = tmp_path / "run"
    short = FamilyPpoConfig("throw_and_catch", frames=32, **TINY)
    run(short, out, progress=False)
    assert json.loads((out / "state.json").read_text())["frames"] == 32
    first = (out / "curve.jsonl").read_text().splitlines()
    result = run(FamilyPpoConfig("throw_and_catch", frames=64, **TINY), out, progress=False)  # grows the budget
    assert result["env_steps"] == 64 and result["train_tasks"] == 2
    lines = (out / "curve.jsonl").read_text().splitlines()
    assert lines[:len(first)] == first and len(lines) == 2 * len(first)
    assert json.loads((out / "result_32.json").read_text())["env_steps"] == 32
    with pytest.raises(ImpactEnvError, match="other settings"):
        run(FamilyPpoConfig("throw_and_catch", frames=96, **{**TINY, "envs_per_task": 4, "batch_size": 32}), out,
            progress=False)

    policy = FamilyPpoPolicy(out)
    env = gym.make("impact_env/ThrowAndCatchTasks-v0", tasks=[3], thrust_noise=0.05)
    episode = run_episode(env, policy, seed=0)  # generated task 3: not one of the training seeds
    assert episode.steps == env.unwrapped.env.core.horizon_steps and np.isfinite(episode.robustness)
    again = run_episode(env, policy, seed=0)
    assert again.robustness == episode.robustness  # deterministic policy, same seed


def test_a_folder_without_a_run_is_a_model_file_error(tmp_path):
    from baselines.batched.family_ppo import FamilyPpoPolicy

    with pytest.raises(ModelFileError, match="family PPO run folder"):
        FamilyPpoPolicy(tmp_path)


def test_cli_parses_task_ranges():
    import argparse

    from baselines.batched.family_ppo import parse_tasks

    assert parse_tasks("3:6") == (3, 4, 5) and parse_tasks("1,9") == (1, 9)
    with pytest.raises(argparse.ArgumentTypeError, match="A:B"):
        parse_tasks("x")
