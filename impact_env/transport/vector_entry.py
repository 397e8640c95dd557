"""The vector entry point of the transport ids (``gymnasium.make_vec``): the batched torch world
(:class:`~impact_env.transport.batched.vector_env.TransportVectorEnv`), imported when a vector env is made.

Gymnasium's ``make_vec(id, num_envs=N)`` picks an id's vector entry point whenever it has one, so without
torch (the ``[rl]`` extra) the call is a typed error that names both ways out instead of an ImportError.
"""

from __future__ import annotations

import importlib.util
from typing import Any

from impact_env.errors import EnvConfigError


def make_vector_env(scenario: Any = None, num_envs: int = 1, **kwargs: Any) -> Any:
    """``TransportVectorEnv(scenario, num_envs, **kwargs)``, truncating at the task's horizon unless
    ``max_episode_steps`` is given; EnvConfigError when torch is not installed."""
    if importlib.util.find_spec("torch") is None:
        raise EnvConfigError("the transport ids' vector env is the batched torch world, and torch is not "
                             "installed: pip install 'impact_env[rl]', or make N pymunk envs with "
                             "gymnasium.make_vec(id, num_envs=N, vectorization_mode='sync')")
    from impact_env.transport.batched.vector_env import TransportVectorEnv

    envs = TransportVectorEnv(scenario, num_envs, **kwargs)
    if "max_episode_steps" not in kwargs:  # impact_env/Transport-v0: the horizon of the scenario given, as its
        envs.max_episode_steps = envs.horizon_steps  # single env's make_with_horizon sets it
    return envs
