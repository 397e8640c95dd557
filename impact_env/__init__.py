"""impact_env: collaborative transport of free-floating objects in microgravity by impacts.

Importing the package registers the Gymnasium environments: one id per shipped scenario (``GYM_IDS``, e.g.
``impact_env/Corridor-v0``), each with ``max_episode_steps`` equal to its task's horizon, and
``impact_env/Transport-v0``, which needs ``scenario=`` and takes its ``max_episode_steps`` from that file.
``gym.make`` can import the package itself: ``gym.make("impact_env:impact_env/Corridor-v0")``. Where
PettingZoo's registry exists it also registers ``impact_env/transport-v0``. PettingZoo's versioned module is
:mod:`impact_env.transport_v0` (``parallel_env``, ``env``, ``raw_env``); ``impact_env.parallel_env``,
``impact_env.env`` and ``impact_env.raw_env`` are the same functions. Every transport id also has a vector entry
point, the batched torch world (``gymnasium.make_vec(id, num_envs=N)``, which picks it, or
``vectorization_mode="vector_entry_point"``; the ``[rl]`` extra: :mod:`impact_env.transport.batched.vector_env`);
torch is imported only when one is made. ``vectorization_mode="sync"`` still makes N pymunk envs.

Tether (anchor-pull) transport: ``impact_env/Tether-v1`` with ``station=`` (a shipped name or a path; its
``max_episode_steps`` from that file) and one id per shipped station (``TETHER_GYM_IDS``, e.g.
``impact_env/TetherL-v1``); PettingZoo ``impact_env/tether-v1`` and the module :mod:`impact_env.tether_v1`. The
``-v0`` tether ids (``TETHER_GYM_IDS_V0``, ``impact_env/Tether-v0``, ``impact_env/tether-v0``,
:mod:`impact_env.tether_v0`) stay registered for one release.
"""

from __future__ import annotations

import gymnasium

from impact_env import moved_modules

# the modules that moved in 0.3.0 (one folder per world family): old path -> new path, for one release
moved_modules.register({
    "impact_env.names": "impact_env.catalogue",
    "impact_env.envs.actions": "impact_env.transport.actions",
    "impact_env.envs.clock": "impact_env.env_shell",
    "impact_env.envs.core": "impact_env.transport.core",
    "impact_env.envs.docstrings": "impact_env.env_docstrings",
    "impact_env.envs.render_support": "impact_env.transport.rendering",
    "impact_env.envs.starts": "impact_env.transport.starts",
    "impact_env.envs.transport": "impact_env.transport.gym_env",
    "impact_env.envs.transport_parallel": "impact_env.transport.pettingzoo_env",
    "impact_env.physics": "impact_env.transport.physics",
    "impact_env.plotting": "impact_env.transport.plotting",
    "impact_env.rendering": "impact_env.transport.rendering",
    "impact_env.scenario": "impact_env.transport.scenario",
    "impact_env.scenarios": "impact_env.transport.scenarios",
    "impact_env.envs.tether": "impact_env.tether.gym_env",
    "impact_env.envs.tether_core": "impact_env.tether.core",
    "impact_env.envs.tether_parallel": "impact_env.tether.pettingzoo_env",
    "impact_env.station": "impact_env.tether.station",
    "impact_env.stations": "impact_env.tether.stations",
    "impact_env.tether_cli": "impact_env.tether.cli",
    "impact_env.tether_physics": "impact_env.tether.physics",
    "impact_env.tether_plotting": "impact_env.tether.plotting",
    "impact_env.tether_rendering": "impact_env.tether.rendering",
})

from impact_env.errors import (  # noqa: E402
    ActionError,
    ImpactEnvError,
    ScenarioError,
    STLBindingError,
    STLError,
    STLSyntaxError,
)
from impact_env.tether.station import Station, load_station, station_names  # noqa: E402
from impact_env.transport.scenario import Scenario, load_scenario, scenario_names  # noqa: E402

__version__ = "0.2.0"

GYM_IDS = {
    "impact_env/Corridor-v0": "corridor",
    "impact_env/ObstacleAvoidance-v0": "obstacle_avoidance",
    "impact_env/ThrowAndCatchExp-v0": "throw_and_catch_exp",
    "impact_env/Relay-v0": "relay",
    "impact_env/TwoObjects-v0": "two_objects",
    "impact_env/PingPongStop-v0": "ping_pong_stop",
    "impact_env/LongThrowTrim-v0": "long_throw_trim",
    "impact_env/NarrowGap-v0": "narrow_gap",
    "impact_env/OneRobotTwoObjects-v0": "one_robot_two_objects",
    "impact_env/TimedVisits-v0": "timed_visits",
    "impact_env/WallStart-v0": "wall_start",
    "impact_env/FourRobots-v0": "four_robots",
    "impact_env/HeldDrift-v0": "held_drift",
}

TETHER_GYM_IDS = {
    "impact_env/TetherL-v1": "L",
    "impact_env/TetherT-v1": "T",
    "impact_env/TetherAlcove-v1": "alcove",
    "impact_env/TetherIssChain-v1": "iss_chain",
    "impact_env/TetherDeadEnd-v1": "dead_end",
}
# version 0 of the tether ids ("eventually in the goal", agents robot_0 ..), kept for one release (removed in 0.4.0)
TETHER_GYM_IDS_V0 = {env_id.replace("-v1", "-v0"): station for env_id, station in TETHER_GYM_IDS.items()}


def _horizon_steps(task_source) -> int:
    """Steps per episode of a scenario or station: its task's horizon (the episode's ``terminated``)."""
    from impact_env.stl import OnlineMonitor

    return OnlineMonitor(task_source.formula, task_source.region_map(), task_source.control_period_s).horizon_steps


TRANSPORT_ENTRY_POINT = "impact_env.transport.gym_env:TransportEnv"
# the batched torch world behind gymnasium.make_vec(id, num_envs=N, vectorization_mode="vector_entry_point"); a
# string, so that torch is imported only when a vector env is made
TRANSPORT_VECTOR_ENTRY_POINT = "impact_env.transport.vector_entry:make_vector_env"


def _add_vector_entry_points() -> None:
    """Every registered id of the transport env (the shipped scenarios' ids, ``Transport-v0`` and any id registered
    with ``scenario=``) gets the batched world as its vector entry point, unless it names one of its own."""
    for spec in gymnasium.registry.values():
        if spec.entry_point == TRANSPORT_ENTRY_POINT and spec.vector_entry_point is None:
            spec.vector_entry_point = TRANSPORT_VECTOR_ENTRY_POINT


def _register() -> None:
    for env_id, scenario in GYM_IDS.items():
        if env_id not in gymnasium.registry:
            gymnasium.register(id=env_id, entry_point=TRANSPORT_ENTRY_POINT, kwargs={"scenario": scenario},
                               vector_entry_point=TRANSPORT_VECTOR_ENTRY_POINT,
                               max_episode_steps=_horizon_steps(load_scenario(scenario)))
    if "impact_env/Transport-v0" not in gymnasium.registry:
        gymnasium.register(id="impact_env/Transport-v0", entry_point="impact_env.transport.gym_env:make_with_horizon",
                           vector_entry_point=TRANSPORT_VECTOR_ENTRY_POINT)
    _add_vector_entry_points()
    # one id per generated-task family: a task of the family per episode, goal-conditioned observations; no
    # max_episode_steps (each task ends at its own horizon)
    from impact_env.transport.family_env import FAMILY_IDS

    for env_id, family in FAMILY_IDS.items():
        if env_id not in gymnasium.registry:
            gymnasium.register(id=env_id, entry_point="impact_env.transport.family_env:TaskFamilyEnv",
                               kwargs={"family": family})
    for ids, cls in ((TETHER_GYM_IDS, "TetherEnv"), (TETHER_GYM_IDS_V0, "TetherEnvV0")):
        for env_id, station in ids.items():
            if env_id not in gymnasium.registry:
                st = load_station(station)
                steps = _horizon_steps(st) if cls == "TetherEnv" else round(st.tf_s / st.control_period_s)
                gymnasium.register(id=env_id, entry_point=f"impact_env.tether.gym_env:{cls}",
                                   kwargs={"station": station}, max_episode_steps=steps)
    # the file given to make sets max_episode_steps (gym_env.make_with_horizon)
    for env_id, entry in (("impact_env/Tether-v1", "make_with_horizon"),
                          ("impact_env/Tether-v0", "make_v0_with_horizon")):
        if env_id not in gymnasium.registry:
            gymnasium.register(id=env_id, entry_point=f"impact_env.tether.gym_env:{entry}")
    try:
        import pettingzoo
        from pettingzoo.env_registry.registration import parallel_registry
    except ImportError:  # an older PettingZoo without a registry: the versioned modules still work
        return
    if "impact_env/transport-v0" not in parallel_registry:
        pettingzoo.register("parallel", "impact_env/transport-v0", entry_point="impact_env.transport_v0:parallel_env")
    for version in ("v1", "v0"):
        if f"impact_env/tether-{version}" not in parallel_registry:
            pettingzoo.register("parallel", f"impact_env/tether-{version}",
                                entry_point=f"impact_env.tether_{version}:parallel_env")


_register()

from impact_env import tether_v0, tether_v1, transport_v0  # noqa: E402, F401 - PettingZoo's versioned modules
from impact_env.transport_v0 import env, parallel_env, raw_env  # noqa: E402

__all__ = [
    "ActionError", "ImpactEnvError", "STLBindingError", "STLError", "STLSyntaxError", "Scenario", "ScenarioError",
    "Station", "__version__", "env", "load_scenario", "load_station", "parallel_env", "raw_env", "scenario_names",
    "station_names",
]
