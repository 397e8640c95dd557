"""The ``impact-env`` command: list, draw and run scenarios and stations.

    impact-env scenarios
    impact-env generate --family F --seed S [--toml task.toml | --out DIR [--count N]]
    impact-env show SCENARIO [--plot setup.png | --out DIR]
    impact-env run SCENARIO --controller zero|random|expert|path/to/model.zip [--seed N] [--episodes K]
                   [--out DIR | --json result.json --plot run.png] [--video out.mp4] [--quiet]

SCENARIO is a shipped name (``impact-env scenarios``) or a path to a TOML file. Tether stations (a shipped
station name, or a TOML file with a ``[station]`` table) work in the same places; ``run`` then takes
``--fidelity kinematic|reel|force`` and ``--energy-penalty``. Each world family answers for its own files
(:mod:`impact_env.transport.cli`, :mod:`impact_env.tether.cli`). Subcommands defined in other packages (e.g.
``plan`` in ``planners/``) join through the ``impact_env.commands`` entry points. Every command speaks the
vocabulary of :mod:`impact_env.cli_options` (``--out DIR`` a folder; ``--json``, ``--plot``, ``--video`` files,
checked before any work).
"""

from __future__ import annotations

import argparse
import sys
from importlib.metadata import entry_points
from pathlib import Path

from impact_env.cli_options import (
    Parser,
    add_files,
    add_out,
    add_quiet,
    add_seed,
    add_tether_options,
    add_transport_options,
    check_outputs,
    legacy_file_out,
    output_path,
    run_outputs,
)
from impact_env.errors import ImpactEnvError
from impact_env.transport.core import REWARD_MODES

COMMANDS_GROUP = "impact_env.commands"

DESCRIPTION = """\
Collaborative transport of free-floating objects in microgravity: by impacts (scenarios) and by tethers
(stations). Plan, fly, train, record and benchmark from one command.

examples:
  impact-env scenarios                                 list the shipped scenarios and stations
  impact-env plan corridor --json plan.json --plot plan.png
  impact-env run corridor --controller expert --plan plan.json --video run.mp4
  impact-env train ppo throw_and_catch_exp --timesteps 50000
"""


def _cmd_scenarios(args: argparse.Namespace) -> int:
    from impact_env.tether.cli import list_stations
    from impact_env.transport.cli import list_scenarios

    list_scenarios()
    print()
    list_stations()
    return 0


def _cmd_show(args: argparse.Namespace) -> int:
    from impact_env.figures import png_path
    from impact_env.tether.station import is_station_file

    legacy_file_out(args, "--plot", (".png",))
    name = Path(args.scenario).stem if args.scenario.endswith(".toml") else args.scenario
    args.plot = str(args.plot or Path(args.out or ".") / f"{name}.png")
    check_outputs({"--plot": args.plot}, {"--out": args.out})
    args.plot = str(png_path(args.plot))
    if is_station_file(args.scenario):
        from impact_env.tether.cli import show_station

        return show_station(args)
    from impact_env.transport.cli import show_scenario

    return show_scenario(args)


def _cmd_run(args: argparse.Namespace) -> int:
    from impact_env.tether.station import is_station_file

    if args.episodes < 1:
        raise ImpactEnvError(f"--episodes must be >= 1, got {args.episodes}")
    if args.seed < 0:
        raise ImpactEnvError(f"--seed must be >= 0, got {args.seed}")
    run_outputs(args)  # before any episode: an unwritable path must not lose the run
    if is_station_file(args.scenario):
        from impact_env.tether.cli import run_station

        return run_station(args)
    from impact_env.transport.cli import run_scenario

    return run_scenario(args)


def _cmd_generate(args: argparse.Namespace) -> int:
    from impact_env.transport.generate import task_name, write_task

    if args.count < 1:
        raise ImpactEnvError(f"--count must be >= 1, got {args.count}")
    if args.seed < 0:
        raise ImpactEnvError(f"--seed must be >= 0, got {args.seed}")
    legacy_file_out(args, "--toml", (".toml",))  # --out task.toml, as the command first spelled it
    if args.toml is not None and args.out is not None:
        raise ImpactEnvError("give --toml PATH (one task) or --out DIR (a folder of <family>_<seed>.toml), not both")
    if args.toml is not None and args.count > 1:
        raise ImpactEnvError(f"--toml is one file; --count {args.count} writes a folder: give --out DIR")
    if args.toml is None and args.out is None:
        if args.count > 1:
            raise ImpactEnvError(f"--count {args.count} writes a folder of tasks: give --out DIR")
        args.toml = "task.toml"
    if args.toml is not None:
        targets = {args.seed: args.toml}
        check_outputs({"--toml": args.toml})
    else:
        check_outputs(folders={"--out": args.out})
        targets = {seed: f"{args.out}/{task_name(args.family, seed)}.toml"
                   for seed in range(args.seed, args.seed + args.count)}
    paths = [write_task(args.family, seed, path) for seed, path in targets.items()]
    for path in paths if len(paths) <= 3 else paths[:1]:
        print(f"wrote {path}")
    if len(paths) > 3:
        print(f"wrote {len(paths)} tasks (seeds {args.seed}..{args.seed + args.count - 1}) to {args.out}/")
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

    from impact_env.transport.generate import FAMILIES

    p = sub.add_parser("generate", help="draw a random task of a family and write it as a scenario file",
                       description="Draw task SEED of a family (the same file on every machine) and write it as an "
                                   "ordinary scenario file, checked. Families: " + ", ".join(FAMILIES) + ".")
    p.add_argument("--family", required=True, help=f"one of {', '.join(FAMILIES)}")
    p.add_argument("--seed", type=int, default=0, help="the task's seed (the first one with --count)")
    p.add_argument("--count", type=int, default=1, help="tasks to write, seeds SEED, SEED + 1, ... (default 1)")
    add_out(p, "<family>_<seed>.toml for each task (see --toml for one file)")
    p.add_argument("--toml", metavar="PATH", default=None, type=output_path,
                   help="the scenario file of one task (default: task.toml when --out is not given)")
    p.set_defaults(func=_cmd_generate)

    p = sub.add_parser("show", help="draw a scenario or station (world, obstacles, regions, bodies, start and end)")
    p.add_argument("scenario", help="a shipped scenario or station name (impact-env scenarios) or a .toml file")
    add_out(p, "<name>.png, the drawing (default: the current folder)")
    add_files(p, plot="the drawing (default: <name>.png in --out)")
    p.set_defaults(func=_cmd_show)

    p = sub.add_parser("run", help="run episodes with a controller and write a JSON summary")
    p.add_argument("scenario", help="a shipped scenario or station name (impact-env scenarios) or a .toml file")
    p.add_argument("--controller", default="zero",
                   help=f"one of {', '.join(available_controllers())}, or a saved model's path (path/to/model.zip, "
                        "as written by impact-env train or bc)")
    add_seed(p)
    p.add_argument("--episodes", type=int, default=1, help="episodes to run")
    add_out(p, "summary.json and episode.png (see --json, --plot)")
    add_files(p, json="JSON summary (success, robustness, impacts, fuel_Ns, per-episode details)",
              plot="PNG of the first episode's trajectories, velocities and impacts",
              video="MP4 of the first episode")
    add_quiet(p, "no line per episode; only the files written")
    p.add_argument("--plan", metavar="JSON", help="a saved plan (impact-env plan ... --json plan.json) for the "
                                                  "expert; planned on the spot if omitted")
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
