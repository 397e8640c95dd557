"""PettingZoo's versioned module of the impact-transport environment, as ``pettingzoo.butterfly.pistonball_v6``.

    from impact_env import transport_v0

    env = transport_v0.parallel_env(scenario="corridor")   # or env() / raw_env() for the AEC form

The version follows the environment's (:class:`~impact_env.transport.pettingzoo_env.TransportParallelEnv`):
a new module ``transport_v1`` would come with any change of dynamics, reward or observations, and this one
would stay as it is.
"""

from impact_env.transport.pettingzoo_env import TransportParallelEnv, env, parallel_env, raw_env  # noqa: F401
