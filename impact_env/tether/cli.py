"""``impact-env scenarios``, ``show`` and ``run`` for tether stations (called by :mod:`impact_env.cli`).

``run`` drives :class:`~impact_env.tether.gym_env.TetherEnv` with the same controllers and episode loop as the
impact scenarios and reports tether numbers (switches, snags, path length, winch work) instead of impacts and
fuel.
"""

from __future__ import annotations

import argparse
from typing import Any

from impact_env.cli_options import check_world_options, print_catalogue, run_and_report, save_summary

TETHER_KEYS = ("switches", "snags", "path_length_m", "winch_work_J", "wall_contacts", "time_to_goal_s",
               "time_at_rest_in_goal_s", "speed_mps", "failed_anchors", "dropped_robots")
# impact-env scenarios: (title, format, value) of each column between the name and the description
COLUMNS = (("robots", ">7", lambda st: st.n_robots), ("k", ">3", lambda st: st.k),
           ("anchors", ">8", lambda st: st.n_anchors), ("w_mps", ">7.2f", lambda st: st.pull_speed_mps),
           ("tf_s", ">6.0f", lambda st: st.tf_s))


def station_options(args: argparse.Namespace) -> dict[str, Any]:
    """``TetherEnv`` keywords from the parsed options (``--faults`` parsed and checked, or None)."""
    from impact_env.tether.faults import parse_faults

    return {"fidelity": args.fidelity, "reward_mode": args.reward_mode, "energy_penalty": args.energy_penalty,
            "pull_speed_mps": args.pull_speed_mps, "max_active": args.max_active,
            "initial_position_noise_m": args.initial_position_noise_m,
            "faults": parse_faults(getattr(args, "faults", None))}


def list_stations() -> None:
    """The table of shipped stations."""
    from impact_env.tether.station import load_station, station_names

    print_catalogue("station", station_names(), load_station, COLUMNS)


def show_station(args: argparse.Namespace) -> int:
    from impact_env.tether.plotting import save_station_figure
    from impact_env.tether.station import load_station

    st = load_station(args.scenario)
    print(f"wrote {save_station_figure(st, args.plot)}")
    print(f"task: {st.task}  ({st.n_anchors} anchors, k = {st.k} of {st.n_robots} robots)")
    return 0


def run_station(args: argparse.Namespace) -> int:
    """``run`` for a tether station: the same loop, tether numbers instead of impacts and fuel."""
    from impact_env.controllers import make_controller
    from impact_env.rollout import EpisodeResult, statistics
    from impact_env.tether.gym_env import TetherEnv
    from impact_env.tether.plotting import plot_tether_run
    from impact_env.tether.station import load_station

    st = load_station(args.scenario)
    check_world_options(args, impact=False, station=True, what=f"station {st.name!r}")
    options = station_options(args)
    env = TetherEnv(st, render_mode="rgb_array" if args.video else None, **options)
    controller = make_controller(args.controller, st, plan=args.plan)
    events = []  # each episode's tether events

    def details(res: EpisodeResult) -> str:
        events.append(list(env.core.events))
        info = res.final_info
        goal = "-" if info["time_to_goal_s"] is None else f"{info['time_to_goal_s']:.0f} s"
        return (f"switches={info['switches']} snags={info['snags']} path={info['path_length_m']:.2f} m "
                f"goal={goal} held={info['time_at_rest_in_goal_s']:.0f} s speed={info['speed_mps']:.3f} m/s")

    results = run_and_report(args, env, controller, details)
    first = results[0]
    if args.plot:
        print(f"wrote {plot_tether_run(st, first.positions, events[0], first.robustness, args.plot)}")
    episodes = [{**r.summary(), **{key: r.final_info[key] for key in TETHER_KEYS}} for r in results]
    for e in episodes:
        e.pop("impacts", None)
        e.pop("fuel_Ns", None)
    summary = {
        "station": st.name, "controller": args.controller, "env_options": options,
        **{key: episodes[0][key] for key in ("success", "robustness", *TETHER_KEYS, "controller_ms")},
        **statistics(results),
        "episodes": episodes,
    }
    save_summary(args.json, summary)
    env.close()
    return 0
