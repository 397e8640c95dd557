"""Gymnasium and PettingZoo environments of impact_env."""

from impact_env.envs.tether import TetherEnv
from impact_env.envs.tether_parallel import TetherParallelEnv
from impact_env.envs.transport import TransportEnv
from impact_env.envs.transport_parallel import TransportParallelEnv, env, parallel_env, raw_env

__all__ = ["TetherEnv", "TetherParallelEnv", "TransportEnv", "TransportParallelEnv", "env", "parallel_env", "raw_env"]
