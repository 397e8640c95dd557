"""impact_env: collaborative transport of free-floating objects in microgravity by impacts.

Importing the package registers the Gymnasium environments (``impact_env/Corridor-v0``,
``impact_env/ObstacleAvoidance-v0``, ``impact_env/ThrowAndCatchExp-v0`` and ``impact_env/Transport-v0``
with ``scenario=``) and, where PettingZoo's registry exists, the parallel environment
``impact_env/transport-v0``. ``impact_env.parallel_env``, ``impact_env.env`` and ``impact_env.raw_env``
are PettingZoo's entry points.

Tether (anchor-pull) transport: ``impact_env/Tether-v0`` with ``station=`` (a shipped name or a path) and one id
per shipped station (``TETHER_GYM_IDS``, e.g. ``impact_env/TetherL-v0``); PettingZoo ``impact_env/tether-v0``
(entry point :func:`impact_env.envs.tether_parallel.parallel_env`).
"""

from __future__ import annotations

import gymnasium

from impact_env.errors import ActionError, ImpactEnvError, ScenarioError, STLBindingError, STLError, STLSyntaxError
from impact_env.scenario import Scenario, load_scenario, scenario_names
from impact_env.station import Station, load_station, station_names

__version__ = "0.1.0"

GYM_IDS = {
    "impact_env/Corridor-v0": "corridor",
    "impact_env/ObstacleAvoidance-v0": "obstacle_avoidance",
    "impact_env/ThrowAndCatchExp-v0": "throw_and_catch_exp",
}

TETHER_GYM_IDS = {
    "impact_env/TetherL-v0": "L",
    "impact_env/TetherT-v0": "T",
    "impact_env/TetherAlcove-v0": "alcove",
    "impact_env/TetherIssChain-v0": "iss_chain",
    "impact_env/TetherDeadEnd-v0": "dead_end",
}


def _register() -> None:
    for env_id, scenario in GYM_IDS.items():
        if env_id not in gymnasium.registry:
            gymnasium.register(id=env_id, entry_point="impact_env.envs.transport:TransportEnv",
                               kwargs={"scenario": scenario})
    if "impact_env/Transport-v0" not in gymnasium.registry:
        gymnasium.register(id="impact_env/Transport-v0", entry_point="impact_env.envs.transport:TransportEnv")
    for env_id, station in TETHER_GYM_IDS.items():
        if env_id not in gymnasium.registry:
            gymnasium.register(id=env_id, entry_point="impact_env.envs.tether:TetherEnv", kwargs={"station": station})
    if "impact_env/Tether-v0" not in gymnasium.registry:
        gymnasium.register(id="impact_env/Tether-v0", entry_point="impact_env.envs.tether:TetherEnv")
    try:
        import pettingzoo
        from pettingzoo.env_registry.registration import parallel_registry
    except ImportError:  # an older PettingZoo without a registry: the entry points below still work
        return
    if "impact_env/transport-v0" not in parallel_registry:
        pettingzoo.register("parallel", "impact_env/transport-v0",
                            entry_point="impact_env.envs.transport_parallel:parallel_env")
    if "impact_env/tether-v0" not in parallel_registry:
        pettingzoo.register("parallel", "impact_env/tether-v0",
                            entry_point="impact_env.envs.tether_parallel:parallel_env")


_register()


def parallel_env(**kwargs):
    """PettingZoo ParallelEnv, one agent per robot; see :class:`impact_env.envs.TransportParallelEnv`."""
    from impact_env.envs.transport_parallel import parallel_env as make

    return make(**kwargs)


def env(**kwargs):
    """PettingZoo AEC env (order-enforced) of :func:`parallel_env`."""
    from impact_env.envs.transport_parallel import env as make

    return make(**kwargs)


def raw_env(**kwargs):
    """PettingZoo AEC env without wrappers."""
    from impact_env.envs.transport_parallel import raw_env as make

    return make(**kwargs)


__all__ = [
    "ActionError", "ImpactEnvError", "STLBindingError", "STLError", "STLSyntaxError", "Scenario", "ScenarioError",
    "Station", "env", "load_scenario", "load_station", "parallel_env", "raw_env", "scenario_names", "station_names",
]
