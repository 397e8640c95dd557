"""``gymnasium.wrappers.RecordVideo`` works with the package's envs after ``pip install impact_env[rl]`` (issue 24:
moviepy, which RecordVideo needs, was only in ``[dev]``)."""

from __future__ import annotations

import configparser

import gymnasium as gym
import numpy as np
import pytest

import impact_env  # noqa: F401 - registers the ids
from tests.paths import ROOT


def test_the_rl_extra_carries_moviepy():
    config = configparser.ConfigParser()
    config.read(ROOT / "setup.cfg")
    rl = [line.split(">")[0].split("=")[0].strip() for line in config["options.extras_require"]["rl"].splitlines()
          if line.strip() and not line.strip().startswith("#")]
    assert "moviepy" in rl


@pytest.mark.parametrize("env_id", ["impact_env/ThrowAndCatchExp-v0", "impact_env/TetherL-v0"])
def test_record_video_writes_an_mp4(env_id, tmp_path):
    pytest.importorskip("moviepy")
    env = gym.wrappers.RecordVideo(gym.make(env_id, render_mode="rgb_array", render_width_px=200,
                                            max_episode_steps=15),
                                   video_folder=str(tmp_path), episode_trigger=lambda episode: True,
                                   disable_logger=True)
    env.reset(seed=0)
    done = False
    while not done:
        _, _, terminated, truncated, _ = env.step(np.zeros(env.action_space.shape, env.action_space.dtype))
        done = terminated or truncated
    env.close()
    videos = list(tmp_path.glob("*.mp4"))
    assert len(videos) == 1 and videos[0].stat().st_size > 1000
