"""PettingZoo's versioned module of the tether-transport environment (deliver and hold, agents ``R1 .. Rn``).

    from impact_env import tether_v1

    env = tether_v1.parallel_env(station="L", fidelity="reel")   # or env() / raw_env() for the AEC form

The version follows :class:`~impact_env.tether.pettingzoo_env.TetherParallelEnv`'s.
"""

from impact_env.tether.pettingzoo_env import TetherParallelEnv, env, parallel_env, raw_env  # noqa: F401
