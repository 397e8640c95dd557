"""Tether (anchor-pull) transport: robots carry a cargo through a station by pulling it toward wall anchors.

The family's file format (:mod:`~impact_env.tether.station`, shipped files in ``stations/``), its pymunk world
(:mod:`~impact_env.tether.physics`), the episode core with the fleet's rules (:mod:`~impact_env.tether.core`),
the Gymnasium and PettingZoo environments (:mod:`~impact_env.tether.gym_env`,
:mod:`~impact_env.tether.pettingzoo_env`), the renderer, the figures and the ``impact-env`` commands for
stations (:mod:`~impact_env.tether.cli`). The public entry points stay at the package's top:
``impact_env.load_station``, ``impact_env.envs.TetherEnv``, :mod:`impact_env.tether_v0`.
"""
