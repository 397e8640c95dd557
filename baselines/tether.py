"""What the learned-baseline tools need for tether stations (``impact-env train ppo L``, ``bench L``).

A station name or file is dispatched here by ``train``, ``bench`` and the sb3 controller: the Gymnasium env is
:class:`~impact_env.tether.gym_env.TetherEnv` (a MultiDiscrete action: one command per robot, so PPO, not SAC),
the hyperparameters are keyed by the station's env id (``impact_env/TetherL-v1``; a user station takes the L
map's), the expert is the tether expert with a plan of the exact planner. The impact world's options (thrust
noise, fuel penalty, restitution, post-impact velocity noise) do not apply; the tether env's own are
``fidelity`` and the initial position noise.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from impact_env.errors import ImpactEnvError

if TYPE_CHECKING:
    from impact_env.tether.station import Station

DEFAULT_ENV_ID = "impact_env/TetherL-v1"
IMPACT_ONLY = {"thrust_noise": 0.0, "fuel_penalty": 0.0, "restitution": None, "impact_velocity_noise_mps": 0.0}


def is_station(name: str) -> bool:
    from impact_env.tether.station import is_station_file

    return is_station_file(name)


def env_id_for_station(name: str) -> str:
    from impact_env import TETHER_GYM_IDS
    from impact_env.tether.station import load_station

    station = load_station(name).name
    return next((env_id for env_id, st in TETHER_GYM_IDS.items() if st == station), DEFAULT_ENV_ID)


def env_options(options: dict[str, Any], name: str) -> dict[str, Any]:
    """The tether env's keywords from the command's options; an impact-only option that is set is an error."""
    out = {}
    for key, value in options.items():
        if key in IMPACT_ONLY:
            if value != IMPACT_ONLY[key]:
                raise ImpactEnvError(f"{key} applies to impact scenarios, not to station {name!r}")
            continue
        out[key] = value
    return out


def make_env(name: str | Station, **options: Any):
    from impact_env.tether.gym_env import TetherEnv

    return TetherEnv(name, **options)


def spaces_of(station: Any):
    """The observation and action spaces of the central tether env for ``station`` and the observation size."""
    import numpy as np
    from gymnasium import spaces

    from impact_env.tether.core import TetherCore

    core = TetherCore(station)
    return (spaces.Box(core.obs_low, core.obs_high, dtype=np.float32),
            spaces.MultiDiscrete([core.n_commands] * core.n_robots), core.obs_size)
