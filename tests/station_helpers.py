"""Station builders shared by the tether tests."""

from __future__ import annotations

import copy

from impact_env.tether.station import Station, station_from_dict

L_POLYGON = [[0, 0], [5, 0], [5, 10], [20, 10], [20, 15], [0, 15]]


def station_dict(polygon=None, *, start=(2.5, 1.5), goal=(18.5, 12.5), anchors=None, count: int = 3,
                 max_active: int = 2, w: float = 0.1, winch: float = 1.0, stop: float = 0.6, t_switch: float = 5.0,
                 mass: float = 20.0, radius: float = 0.3, restitution: float = 0.2, tf: float = 600.0,
                 period: float = 1.0, substeps: int = 10) -> dict:
    """A station as a parsed TOML document; by default the L map of the thesis with 2.5 m anchor spacing."""
    return {
        "name": "test_station", "restitution": restitution, "tf_s": tf, "control_period_s": period,
        "substeps": substeps,
        "station": {"polygon": copy.deepcopy(polygon if polygon is not None else L_POLYGON)},
        "anchors": copy.deepcopy(anchors) if anchors is not None else {"spacing_m": 2.5},
        "cargo": {"mass_kg": mass, "radius_m": radius, "start_m": list(start)},
        "goal": {"center_m": list(goal), "half_size_m": 0.5},
        "robots": {"count": count, "max_active": max_active, "pull_speed_mps": w, "winch_force_limit_N": winch,
                   "stop_radius_m": stop, "switch_time_s": t_switch},
    }


def make_station(polygon=None, **kwargs) -> Station:
    return station_from_dict(station_dict(polygon, **kwargs))
