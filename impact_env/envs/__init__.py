"""Gymnasium and PettingZoo environments of impact_env."""

from impact_env.envs.transport import TransportEnv
from impact_env.envs.transport_parallel import TransportParallelEnv, env, parallel_env, raw_env

__all__ = ["TransportEnv", "TransportParallelEnv", "env", "parallel_env", "raw_env"]
