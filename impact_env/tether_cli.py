"""``impact-env show`` and ``run`` for tether stations (called by :mod:`impact_env.cli` for station files).

``run`` drives :class:`~impact_env.envs.tether.TetherEnv` with the same controllers and episode loop as the
impact scenarios and reports tether numbers (switches, snags, path length, winch work) instead of impacts and
fuel.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from impact_env.errors import ImpactEnvError


def show_station(args: argparse.Namespace) -> int:
    from impact_env.station import load_station
    from impact_env.tether_plotting import save_station_figure

    st = load_station(args.scenario)
    print(f"wrote {save_station_figure(st, args.out)}")
    print(f"task: {st.task}  ({st.n_anchors} anchors, k = {st.k} of {st.n_robots} robots)")
    return 0


def run_station(args: argparse.Namespace) -> int:
    """``run`` for a tether station: the same loop, tether numbers instead of impacts and fuel."""
    from impact_env.controllers import make_controller
    from impact_env.envs.tether import TetherEnv
    from impact_env.rollout import run_episode, write_video
    from impact_env.station import load_station
    from impact_env.tether_plotting import plot_tether_run

    st = load_station(args.scenario)
    for flag, value, default in (("--restitution", args.restitution, None), ("--thrust-noise", args.thrust_noise, 0.0),
                                 ("--fuel-penalty", args.fuel_penalty, 0.0)):
        if value != default:
            raise ImpactEnvError(f"{flag} applies to impact scenarios, not to station {st.name!r}")
    if args.reward_mode not in ("dense", "sparse"):
        raise ImpactEnvError(f"--reward-mode {args.reward_mode} applies to impact scenarios; a station takes dense or "
                             "sparse")
    options = {"fidelity": args.fidelity, "reward_mode": args.reward_mode, "energy_penalty": args.energy_penalty,
               "pull_speed_mps": args.pull_speed_mps, "max_active": args.max_active,
               "initial_position_noise_m": args.initial_position_noise_m}
    env = TetherEnv(st, render_mode="rgb_array" if args.video else None, **options)
    controller = make_controller(args.controller, st, plan=args.plan)
    results, events = [], []
    for k in range(args.episodes):
        seed = args.seed + k
        res = run_episode(env, controller, seed=seed, record_frames=bool(args.video) and k == 0)
        if hasattr(controller, "report"):
            res.extra = controller.report()
        results.append(res)
        events.append(list(env.core.events))
        info = res.final_info
        print(f"episode {k + 1}/{args.episodes} seed={seed}: robustness={res.robustness:+.4f} m "
              f"success={res.success} switches={info['switches']} snags={info['snags']} "
              f"path={info['path_length_m']:.2f} m ({res.steps} steps, {res.wall_time_s:.2f} s)", flush=True)
    first = results[0]
    if args.video:
        write_video(first.frames, args.video, fps=env.metadata["render_fps"])
        print(f"wrote {args.video}")
    if args.plot:
        print(f"wrote {plot_tether_run(st, first.positions, events[0], first.robustness, args.plot)}")
    tether_keys = ("switches", "snags", "path_length_m", "winch_work_J", "wall_contacts")
    episodes = [{**r.summary(), **{key: r.final_info[key] for key in tether_keys}} for r in results]
    for e in episodes:
        e.pop("impacts", None)
        e.pop("fuel_Ns", None)
    summary = {
        "station": st.name, "controller": args.controller, "env_options": options,
        **{key: episodes[0][key] for key in ("success", "robustness", *tether_keys, "controller_ms")},
        "success_rate": float(np.mean([r.success for r in results])),
        "robustness_mean": float(np.mean([r.robustness for r in results])),
        "robustness_std": float(np.std([r.robustness for r in results])),
        "episodes": episodes,
    }
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(summary, indent=2))
        print(f"wrote {args.json}")
    env.close()
    return 0
