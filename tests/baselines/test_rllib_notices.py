"""An RLlib run's terminal holds no notices that ask nothing of the user (issue 24: RLlib runs flooded the terminal
with deprecation and auth warnings), and every other warning still shows."""

from __future__ import annotations

import logging
import subprocess
import sys

import pytest

from baselines.rllib_notices import NOTICES, quiet_notices
from tests.paths import ROOT


def test_the_notices_are_dropped_and_other_warnings_kept(caplog):
    quiet_notices()
    quiet_notices()  # idempotent: one filter per logger
    for name, texts in NOTICES.items():
        logger = logging.getLogger(name)
        assert sum(type(f).__name__ == "NoticeFilter" for f in logger.filters) == 1
        with caplog.at_level(logging.WARNING, logger=name):
            caplog.clear()
            for text in texts:
                logger.warning("2 lines: %s, and more", text)
            logger.warning("a real problem the user must see")
            logger.error("an error")
        assert [r.getMessage() for r in caplog.records] == ["a real problem the user must see", "an error"]


SCRIPT = """
import gymnasium as gym
from baselines.rllib_notices import quiet_notices
quiet_notices()
from impact_env.sweep import EngineConfig, connect_ray
import ray
connect_ray(EngineConfig("ray", workers=1))
from ray.rllib.algorithms.ppo import PPOConfig
box = gym.spaces.Box(-1.0, 1.0, (3,))
config = PPOConfig().environment(observation_space=box, action_space=box)
config.validate()
spec = config.get_default_rl_module_spec()
spec.observation_space, spec.action_space = box, box
spec.build()
ray.shutdown()
print("built")
"""


@pytest.mark.xdist_group("ray")
def test_a_driver_that_starts_ray_and_builds_ppo_prints_no_notice():
    pytest.importorskip("ray.rllib")
    done = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, cwd=ROOT, timeout=600,
                          env={**__import__("os").environ, "PYTHONPATH": str(ROOT)})
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip().endswith("built")
    for texts in NOTICES.values():
        for text in texts:
            assert text not in done.stderr, done.stderr[-2000:]


def test_env_runners_and_the_driver_install_the_filters():
    import inspect

    from baselines import rllib_env, rllib_train

    assert "quiet_notices()" in inspect.getsource(rllib_env.make_env)
    assert "quiet_notices()" in inspect.getsource(rllib_train.train_rllib)
