"""PettingZoo's versioned module of the tether-transport environment, version 0, kept for one release (removed
in 0.4.0; use :mod:`impact_env.tether_v1`): agents ``robot_0 ..``, the "eventually in the goal" task.

    from impact_env import tether_v0

    env = tether_v0.parallel_env(station="L", fidelity="reel")   # or env() / raw_env() for the AEC form
"""

from impact_env.tether.pettingzoo_env import TetherParallelEnvV0 as TetherParallelEnv, env_v0 as env, parallel_env_v0 as parallel_env, raw_env_v0 as raw_env  # noqa: E501, F401
