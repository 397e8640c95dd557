"""PettingZoo's versioned module of the tether-transport environment, version 0, kept for one release (removed
in 0.4.0; use :mod:`impact_env.tether_v1`): agents ``robot_0 ..``, the "eventually in the goal" task.

    from impact_env import tether_v0

    env = tether_v0.parallel_env(station="L", fidelity="reel")   # or env() / raw_env() for the AEC form
"""

from impact_env.tether.pettingzoo_env import TetherParallelEnvV0 as TetherParallelEnv
from impact_env.tether.pettingzoo_env import env_v0 as env
from impact_env.tether.pettingzoo_env import parallel_env_v0 as parallel_env
from impact_env.tether.pettingzoo_env import raw_env_v0 as raw_env

__all__ = ["TetherParallelEnv", "env", "parallel_env", "raw_env"]
