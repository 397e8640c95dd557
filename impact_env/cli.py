"""The ``impact-env`` command: list, draw and run scenarios and stations.

    impact-env scenarios
    impact-env show SCENARIO --out setup.png
    impact-env run SCENARIO --controller zero|random|expert|path/to/model.zip [--seed N] [--episodes K]
                   [--video out.mp4] [--json result.json] [--plot run.png]

SCENARIO is a shipped name (``impact-env scenarios``) or a path to a TOML file. Tether stations (a shipped
station name, or a TOML file with a ``[station]`` table) work in the same places; ``run`` then takes
``--fidelity kinematic|reel|force`` and ``--energy-penalty``. Subcommands defined in
other packages (e.g. ``plan`` in ``planners/``) join through the ``impact_env.commands`` entry points.
"""

from __future__ import annotations

import argparse
import json
import sys
import textwrap
from importlib.metadata import entry_points
from pathlib import Path

import numpy as np

from impact_env.cli_options import Parser, add_tether_options, add_transport_options, transport_options
from impact_env.envs.core import REWARD_MODES
from impact_env.errors import ImpactEnvError

COMMANDS_GROUP = "impact_env.commands"

DESCRIPTION = """\
Collaborative transport of free-floating objects in microgravity: by impacts (scenarios) and by tethers
(stations). Plan, fly, train, record and benchmark from one command.

examples:
  impact-env scenarios                                 list the shipped scenarios and stations
  impact-env plan corridor --out plan.json --plot plan.png
  impact-env run corridor --controller expert --plan plan.json --video run.mp4
  impact-env train ppo throw_and_catch_exp --timesteps 50000
"""


def _cmd_scenarios(args: argparse.Namespace) -> int:
    from impact_env.scenario import load_scenario, scenario_names

    rows = []
    for name in scenario_names():
        sc = load_scenario(name)
        rows.append((name, len(sc.robots), len(sc.objects), sc.restitution, sc.tf_s, sc.description))
    print(f"{'name':<22}{'robots':>7}{'objects':>8}{'e':>6}{'tf_s':>7}  description")
    for name, nr, no, e, tf, desc in rows:
        print(f"{name:<22}{nr:>7}{no:>8}{e:>6.2f}{tf:>7.0f}  {desc}")
    from impact_env.station import load_station, station_names

    print(f"\n{'station':<22}{'robots':>7}{'k':>3}{'anchors':>8}{'w_mps':>7}{'tf_s':>6}  description")
    for name in station_names():
        st = load_station(name)
        print(f"{name:<22}{st.n_robots:>7}{st.k:>3}{st.n_anchors:>8}{st.pull_speed_mps:>7.2f}{st.tf_s:>6.0f}  "
              f"{st.description}")
    return 0


def _cmd_show(args: argparse.Namespace) -> int:
    from impact_env.plotting import save_scenario_figure
    from impact_env.scenario import load_scenario
    from impact_env.station import is_station_file

    if is_station_file(args.scenario):
        from impact_env.tether_cli import show_station

        return show_station(args)
    sc = load_scenario(args.scenario)
    path = save_scenario_figure(sc, args.out)
    print(f"wrote {path}")
    print(textwrap.fill(f"task: {' '.join(sc.task.split())}", width=100, subsequent_indent="      "))
    return 0


def _env_kwargs(args: argparse.Namespace) -> dict:
    return transport_options(args)


def _cmd_run(args: argparse.Namespace) -> int:
    from impact_env.controllers import make_controller
    from impact_env.envs.transport import TransportEnv
    from impact_env.plotting import count_impacts
    from impact_env.rollout import run_episode, write_video
    from impact_env.scenario import load_scenario
    from impact_env.station import is_station_file

    if args.episodes < 1:
        raise ImpactEnvError(f"--episodes must be >= 1, got {args.episodes}")
    if args.seed < 0:
        raise ImpactEnvError(f"--seed must be >= 0, got {args.seed}")
    if is_station_file(args.scenario):
        from impact_env.tether_cli import run_station

        return run_station(args)
    if (args.fidelity, args.energy_penalty, args.pull_speed_mps, args.max_active) != ("kinematic", 0.0, None, None):
        raise ImpactEnvError("--fidelity, --energy-penalty, --pull-speed-mps and --max-active apply to tether "
                             "stations, not to impact scenarios")
    sc = load_scenario(args.scenario)
    env = TransportEnv(sc, render_mode="rgb_array" if args.video else None, **_env_kwargs(args))
    controller = make_controller(args.controller, sc, plan=args.plan, trust_pickle=True if args.trust_pickle else None,
                                 allow_other_scenario=True if args.allow_other_scenario else None)
    results = []
    for k in range(args.episodes):
        seed = args.seed + k
        res = run_episode(env, controller, seed=seed, record_frames=bool(args.video) and k == 0)
        if hasattr(controller, "report"):  # e.g. the expert's planned-versus-executed numbers
            res.extra = controller.report()
        results.append(res)
        hits, contacts = count_impacts(sc, res.impacts)
        print(f"episode {k + 1}/{args.episodes} seed={seed}: robustness={res.robustness:+.4f} m "
              f"success={res.success} impacts={hits} (robot-object; {contacts} contacts in all) "
              f"fuel={res.fuel_Ns:.2f} N s ({res.steps} steps, {res.wall_time_s:.2f} s)", flush=True)
    first = results[0]
    if args.video:
        write_video(first.frames, args.video, fps=env.metadata["render_fps"])
        print(f"wrote {args.video}")
    if args.plot:
        if hasattr(controller, "plot_episode"):  # the expert draws executed against planned (Fig. 6)
            controller.plot_episode(first, args.plot)
        else:
            from impact_env.plotting import plot_run

            plot_run(sc, first.times_s, first.positions, first.impacts, first.robustness, args.plot)
        print(f"wrote {args.plot}")
    summary = {
        "scenario": sc.name, "controller": args.controller, "env_options": _env_kwargs(args),
        # the first episode's numbers at the top level; every episode under "episodes"
        **{k: v for k, v in first.summary().items()
           if k in ("success", "robustness", "impacts", "fuel_Ns", "controller_ms", "controller_report")},
        "success_rate": float(np.mean([r.success for r in results])),
        "robustness_mean": float(np.mean([r.robustness for r in results])),
        "robustness_std": float(np.std([r.robustness for r in results])),
        "episodes": [r.summary() for r in results],
    }
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(summary, indent=2))
        print(f"wrote {args.json}")
    env.close()
    return 0


def _version() -> str:
    from impact_env import __version__

    return f"impact-env {__version__}"


def build_parser() -> argparse.ArgumentParser:
    from impact_env.controllers import available_controllers

    parser = Parser(prog="impact-env", description=DESCRIPTION)
    parser.add_argument("--version", action="version", version=_version())
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("scenarios", help="list the shipped scenarios and tether stations")
    p.set_defaults(func=_cmd_scenarios)

    p = sub.add_parser("show", help="draw a scenario or station (world, obstacles, regions, bodies, start and end)")
    p.add_argument("scenario", help="a shipped scenario or station name (impact-env scenarios) or a .toml file")
    p.add_argument("--out", default="setup.png", help="output image")
    p.set_defaults(func=_cmd_show)

    p = sub.add_parser("run", help="run episodes with a controller and write a JSON summary")
    p.add_argument("scenario", help="a shipped scenario or station name (impact-env scenarios) or a .toml file")
    p.add_argument("--controller", default="zero",
                   help=f"one of {', '.join(available_controllers())}, or a saved model's path (path/to/model.zip, "
                        "as written by impact-env train or bc)")
    p.add_argument("--seed", type=int, default=0, help="seed of the first episode (episode k uses seed + k)")
    p.add_argument("--episodes", type=int, default=1, help="episodes to run")
    p.add_argument("--video", metavar="MP4", help="mp4 of the first episode")
    p.add_argument("--json", metavar="PATH", help="JSON summary (success, robustness, impacts, fuel_Ns, per-episode "
                                                  "details)")
    p.add_argument("--plot", metavar="PNG", help="PNG of the first episode's trajectories, velocities and impacts")
    p.add_argument("--plan", metavar="JSON", help="a saved plan (impact-env plan ... --out plan.json) for the expert; "
                                                  "planned on the spot if omitted")
    add_transport_options(p, REWARD_MODES)
    add_tether_options(p)
    p.add_argument("--trust-pickle", action="store_true",
                   help="a controller may unpickle its files (e.g. an old model folder's vecnormalize.pkl); a "
                        "pickle can run any code: only for files you made yourself")
    p.add_argument("--allow-other-scenario", action="store_true",
                   help="fly a saved model on another scenario than the one it was trained on (refused otherwise)")
    p.set_defaults(func=_cmd_run)

    for ep in entry_points(group=COMMANDS_GROUP):
        ep.load()(sub)  # each plug-in adds its own subparser and sets func
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except ImpactEnvError as exc:
        print(f"impact-env: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
