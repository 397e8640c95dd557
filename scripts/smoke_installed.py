"""Smoke test of an installed impact_env, run from outside the source tree (``make wheel-check`` runs it in a
fresh venv that has only the wheel and its dependencies).

It checks that the installed package, not a checkout, is imported; that its data files came along (scenarios,
stations, hyperparameters) and its compiled helpers were built and are used (the substep loop, the STL
monitor); that ``gym.make`` works for an impact and a tether id; and that one planned expert episode (MILP plan,
replanner, MPC) solves the lab's throw and catch.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path


def main() -> int:
    import gymnasium as gym
    import numpy as np

    import impact_env
    from impact_env import scenario_names, station_names

    where = Path(impact_env.__file__).resolve()
    assert "site-packages" in where.parts, f"impact_env imported from {where}, not from the installed wheel"
    assert {"corridor", "obstacle_avoidance", "throw_and_catch_exp"} <= set(scenario_names())
    assert {"L", "T", "alcove", "iss_chain", "dead_end"} <= set(station_names())
    from importlib.resources import files

    assert files("baselines").joinpath("hyperparams", "ppo.yml").is_file()

    import impact_env.stl.compiled
    from impact_env.transport import native

    assert native.available(), "the compiled substep loop (impact_env.transport._substeps) was not built"
    assert impact_env.stl.compiled._cmonitor is not None, "the compiled STL monitor was not built"
    env = gym.make("impact_env/Corridor-v0")
    assert env.spec.max_episode_steps == 1000
    obs, info = env.reset(seed=0)
    core = env.unwrapped.core
    assert core.world._loop is not None and type(core.monitor) is impact_env.stl.compiled.CompiledMonitor
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    assert obs.shape == env.observation_space.shape and isinstance(reward, float)
    tether = gym.make("impact_env/TetherL-v1", fidelity="reel")
    tether.reset(seed=0)
    tether.step(np.zeros(tether.action_space.shape, dtype=np.int64))
    from impact_env.tether import native as tether_native

    assert tether_native.available(), "the compiled kinematic loop (impact_env.tether._substeps) was not built"
    tether = gym.make("impact_env/TetherL-v1", fidelity="kinematic")
    tether.reset(seed=0)
    assert tether.unwrapped.core.world._kinematic_loop is not None
    tether.step(np.zeros(tether.action_space.shape, dtype=np.int64))

    from planners.expert import Expert

    env = gym.make("impact_env/ThrowAndCatchExp-v0")
    expert = Expert("throw_and_catch_exp")  # plans with the MILP (HiGHS)
    obs, info = env.reset(seed=0)
    expert.reset()
    done = False
    while not done:
        obs, reward, terminated, truncated, info = env.step(expert.act(obs, info))
        done = terminated or truncated
    assert info["is_success"] and info["robustness"] > 0.35, info["robustness"]

    version = subprocess.run(["impact-env", "--version"], capture_output=True, text=True, check=True).stdout.strip()
    assert version == f"impact-env {impact_env.__version__}", version
    print(f"smoke test passed: impact_env {impact_env.__version__} from {where.parent}; expert robustness "
          f"{info['robustness']:.3f} m")
    return 0


if __name__ == "__main__":
    sys.exit(main())
