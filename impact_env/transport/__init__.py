"""Impact transport: robots move free-floating objects only by hitting them, with exact restitution.

The family's file format (:mod:`~impact_env.transport.scenario`, shipped files in ``scenarios/``), its pymunk
world (:mod:`~impact_env.transport.physics`), the episode core (:mod:`~impact_env.transport.core`), the
Gymnasium and PettingZoo environments (:mod:`~impact_env.transport.gym_env`,
:mod:`~impact_env.transport.pettingzoo_env`), the renderer, the figures and the ``impact-env`` commands for
scenarios (:mod:`~impact_env.transport.cli`). The public entry points stay at the package's top:
``impact_env.load_scenario``, ``impact_env.envs.TransportEnv``, :mod:`impact_env.transport_v0`.
"""
