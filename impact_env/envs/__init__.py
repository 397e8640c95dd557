"""The Gymnasium and PettingZoo environments of both world families, at the path users import them from.

The classes live with their family (:mod:`impact_env.transport.gym_env`, :mod:`impact_env.tether.gym_env`, ...);
``env``, ``parallel_env`` and ``raw_env`` are the transport environment's PettingZoo entry points.
"""

from impact_env.tether.gym_env import TetherEnv
from impact_env.tether.pettingzoo_env import TetherParallelEnv
from impact_env.transport.gym_env import TransportEnv
from impact_env.transport.pettingzoo_env import TransportParallelEnv, env, parallel_env, raw_env

__all__ = ["TetherEnv", "TetherParallelEnv", "TransportEnv", "TransportParallelEnv", "env", "parallel_env", "raw_env"]
