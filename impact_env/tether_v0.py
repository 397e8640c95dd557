"""PettingZoo's versioned module of the tether-transport environment.

    from impact_env import tether_v0

    env = tether_v0.parallel_env(station="L", fidelity="reel")   # or env() / raw_env() for the AEC form

The version follows :class:`~impact_env.envs.tether_parallel.TetherParallelEnv`'s.
"""

from impact_env.envs.tether_parallel import TetherParallelEnv, env, parallel_env, raw_env

__all__ = ["TetherParallelEnv", "env", "parallel_env", "raw_env"]
