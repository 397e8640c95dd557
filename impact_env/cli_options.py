"""What every ``impact-env`` subcommand shares: the parser class, one option vocabulary and ``run``'s outputs.

:class:`Parser` prints each option's default in ``--help``, adds "did you mean" to argparse's errors for a
mistyped subcommand, choice or option, and turns off argparse's prefix matching (``--timestep`` is an error,
not ``--timesteps``). The vocabulary, the same on every command that has the option:

- ``--out DIR`` is always a folder, into which a command writes its outputs under fixed names; ``--json PATH``,
  ``--plot PATH`` (a PNG) and ``--video PATH`` (an MP4) are single files, wherever they are asked for;
- ``--seed`` and the noise options wherever episodes run; ``--quiet`` (no progress lines) on every long command;
- the environment options are named exactly as the environments' keyword arguments, hyphenated
  (``--reward-mode`` is ``reward_mode=``, ``--initial-position-noise-m`` is ``initial_position_noise_m=``), so
  what works on the command line works in ``gym.make`` and back.

Every output path is checked before the work starts (:func:`check_outputs`) and written atomically
(:mod:`impact_env.results_store`). The spellings of 0.2 (``--out FILE``, ``--no-progress``) still work in 0.3,
with a deprecation message (:func:`deprecated`), and go in :data:`REMOVED_IN`.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, NoReturn

from impact_env.catalogue import suggestion
from impact_env.results_store import check_output_file, check_output_folder, write_atomic

# options renamed in 0.2.0 to match the environments' keywords
RENAMED = {"--reward": "--reward-mode", "--init-noise": "--initial-position-noise-m"}
REMOVED_IN = "0.4.0"  # the release in which the spellings deprecated in 0.3.0 go
# the tether stations' options and their defaults; an impact scenario refuses them when set, and vice versa
STATION_DEFAULTS = {"fidelity": "kinematic", "energy_penalty": 0.0, "pull_speed_mps": None, "max_active": None,
                    "faults": None}
IMPACT_DEFAULTS = {"restitution": None, "thrust_noise": 0.0, "fuel_penalty": 0.0, "impact_velocity_noise_mps": 0.0}

REWARD_HELP = ("dense: per-step increment of the STL robustness estimate (sums to the final robustness); sparse: "
               "the final robustness on the last step; conjuncts: increment of the mean robustness of the task's "
               "conjuncts (impact scenarios only)")


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Descriptions as written; every option's help ends with its default unless it says it already."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        shown = not (action.default is None or action.default is False or action.default == argparse.SUPPRESS)
        if action.option_strings and shown and "default" not in text:
            text += " (default: %(default)s)"
        return text


class Parser(argparse.ArgumentParser):
    """argparse with defaults in the help and "did you mean" in errors (subparsers inherit the class)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("formatter_class", HelpFormatter)
        kwargs.setdefault("allow_abbrev", False)  # --timestep must not silently mean --timesteps
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> NoReturn:  # noqa: D401 - argparse's hook
        choice = re.search(r"invalid choice: '([^']*)' \(choose from (.*)\)", message)
        if choice:
            options = re.findall(r"'([^']*)'", choice.group(2))
            message += suggestion(choice.group(1), options)
        unknown = re.search(r"unrecognized arguments: (.*)", message)
        if unknown:
            known = [o for a in self._all_actions() for o in a.option_strings]
            hints = []
            for word in unknown.group(1).split():
                flag = word.split("=")[0]
                if not flag.startswith("--"):
                    continue
                if flag in RENAMED:
                    hints.append(f"{flag} is now {RENAMED[flag]}")
                elif hint := suggestion(flag, known):
                    hints.append(f"{flag}{hint}")
            if hints:
                message += "; " + "; ".join(hints)
        super().error(message)

    def parse_args(self, args=None, namespace=None):
        import sys

        self._argv = list(sys.argv[1:] if args is None else args)
        return super().parse_args(args, namespace)

    def _all_actions(self) -> list[argparse.Action]:
        """This parser's actions and those of the subcommand named on the command line, if any."""
        actions = list(self._actions)
        words = getattr(self, "_argv", [])
        for action in self._actions:
            if isinstance(action, argparse._SubParsersAction):
                picked = next((w for w in words if w in action.choices), None)
                if picked is not None:
                    actions += action.choices[picked]._actions
        return actions


# ------------------------------------------------------------------------------------------ the vocabulary


def deprecated(old: str, new: str) -> None:
    """Say on stderr that the 0.2 spelling ``old`` is now ``new`` (it keeps working until :data:`REMOVED_IN`)."""
    print(f"impact-env: warning: {old} is deprecated and goes in {REMOVED_IN}: use {new}", file=sys.stderr,
          flush=True)


class _DeprecatedQuiet(argparse.Action):
    """``--no-progress`` (0.2, ``train`` only): sets ``quiet`` and says it is deprecated."""

    def __init__(self, option_strings: Sequence[str], dest: str, **kwargs: Any) -> None:
        super().__init__(option_strings, "quiet", nargs=0, default=None, help=argparse.SUPPRESS)  # --quiet sets it

    def __call__(self, parser, namespace, values, option_string=None) -> None:
        deprecated(str(option_string), "--quiet")
        namespace.quiet = True


def add_quiet(p: argparse.ArgumentParser, what: str = "no progress lines; only the result and the files written",
              legacy_no_progress: bool = False) -> None:
    """``--quiet`` (and, on ``train``, its 0.2 spelling ``--no-progress``)."""
    p.add_argument("--quiet", action="store_true", help=what)
    if legacy_no_progress:
        p.add_argument("--no-progress", action=_DeprecatedQuiet)


def output_path(text: str) -> str:
    """argparse's type of every output path: an empty one (``--plot ""``, which would mean "not given" further
    on, or the current folder) and one with a NUL byte (which no file system takes) are usage errors."""
    if not text.strip():
        raise argparse.ArgumentTypeError(f"{text!r} is an empty path: give a file or folder path")
    if "\0" in text:
        raise argparse.ArgumentTypeError(f"{text!r} contains a NUL byte, which no path can")
    return text


def add_out(p: argparse.ArgumentParser, what: str, default: str | None = None) -> None:
    """``--out DIR``: the folder of the command's outputs."""
    p.add_argument("--out", metavar="DIR", default=default, type=output_path, help=f"output folder: {what}")


def add_run_folder(p: argparse.ArgumentParser, contents: str, default_name: str, resume: str | None = None) -> None:
    """A trainer's run folder: ``--out DIR`` (holding ``contents``), else ``<--runs-dir>/<default_name>``; with
    ``resume`` (its help text), ``--resume`` too."""
    add_out(p, f"the run folder, with {contents} (default: <--runs-dir>/{default_name})")
    p.add_argument("--runs-dir", default="runs", type=output_path, help="parent of the default run folder")
    if resume is not None:
        p.add_argument("--resume", action="store_true", help=resume)


def add_files(p: argparse.ArgumentParser, **what: str) -> None:
    """The single-file options ``--json PATH``, ``--plot PATH``, ``--video PATH`` that ``what`` names, each
    with its help text (``add_files(p, json="the plan", plot="a figure of it")``)."""
    metavars = {"json": "PATH", "plot": "PNG", "video": "MP4"}
    for name, text in what.items():
        p.add_argument(f"--{name}", metavar=metavars[name], default=None, type=output_path, help=text)


def legacy_file_out(args: argparse.Namespace, option: str, suffixes: tuple[str, ...]) -> None:
    """0.2's ``--out FILE`` where 0.3 has a single-file option: an ``--out`` ending in one of ``suffixes``
    (``.png``) becomes ``option`` (``--plot``), with a deprecation message; ``--out`` is a folder now."""
    out = getattr(args, "out", None)
    if out is None or Path(out).suffix.lower() not in suffixes:
        return
    dest = option.lstrip("-").replace("-", "_")
    if getattr(args, dest, None) is not None:
        return  # both given: --out is taken as the folder it now is
    deprecated(f"--out {out} (a file)", f"{option} {out}; --out is a folder now")
    setattr(args, dest, out)
    args.out = None


def in_folder(args: argparse.Namespace, option: str, name: str) -> str | None:
    """The single file of ``option`` (``--json``): its own path if given, else ``name`` inside ``--out``, else
    None."""
    given = getattr(args, option.lstrip("-").replace("-", "_"), None)
    if given is not None:
        return given
    return str(Path(args.out) / name) if getattr(args, "out", None) is not None else None


def figure_suffixes() -> list[str]:
    """The suffixes a figure can be saved with (matplotlib picks the format from it): ``.png``, ``.pdf``, ..."""
    from matplotlib.backend_bases import FigureCanvasBase

    return sorted(f".{kind}" for kind in FigureCanvasBase.get_supported_filetypes())


def check_outputs(files: Mapping[str, str | None] | None = None,
                  folders: Mapping[str, str | None] | None = None) -> None:
    """Every output file and folder checked before any work (``{option: path}``; None: not asked for), so that
    an unwritable path is an :class:`~impact_env.errors.OutputPathError` naming it, at the start, not a
    traceback at the end that loses the results. A video must end in ``.mp4``; a ``--plot`` without a suffix
    is written as ``PATH.png``, and both paths are checked (``--plot /dev/full`` is refused, not turned into
    ``/dev/full.png``)."""
    for option, path in dict(folders or {}).items():
        if path is not None:
            check_output_folder(path, option)
    for option, path in dict(files or {}).items():
        if path is None:
            continue
        if option == "--video" and Path(path).suffix.lower() != ".mp4":
            from impact_env.errors import OutputPathError

            raise OutputPathError(f"--video {path} must end in .mp4 (an H.264 video)")
        check_output_file(path, option)
        if option == "--plot" and Path(path).suffix and Path(path).suffix.lower() not in figure_suffixes():
            from impact_env.errors import OutputPathError

            raise OutputPathError(f"--plot {path}: {Path(path).suffix} is not an image format matplotlib writes "
                                  f"({', '.join(figure_suffixes())}); .png, or no suffix, gives a PNG")
        if option == "--plot" and not Path(path).suffix:  # the figure goes to PATH.png: check that too, but only
            check_output_file(Path(path).with_suffix(".png"), option)  # once PATH itself is not /dev/full


def add_seed(p: argparse.ArgumentParser, what: str = "seed of the first episode (episode k uses seed + k)") -> None:
    p.add_argument("--seed", type=int, default=0, help=what)


def add_transport_options(p: argparse.ArgumentParser, reward_modes: tuple[str, ...]) -> None:
    """The impact environments' options (``TransportEnv`` keywords)."""
    p.add_argument("--reward-mode", choices=reward_modes, default="dense", help=REWARD_HELP)
    p.add_argument("--fuel-penalty", type=float, default=0.0, metavar="C", help="reward cost per N s of fuel")
    p.add_argument("--restitution", type=float, default=None, metavar="E",
                   help="simulate with this restitution instead of the scenario's (model mismatch)")
    p.add_argument("--thrust-noise", type=float, default=0.0, metavar="STD",
                   help="standard deviation of multiplicative thrust noise (0.05 = 5%%)")
    p.add_argument("--initial-position-noise-m", type=float, default=0.0, metavar="R",
                   help="objects (the cargo, for a station) start uniformly within this radius (m) of their position")
    p.add_argument("--impact-velocity-noise-mps", type=float, default=0.0, metavar="M",
                   help="impact scenarios only: a uniform error in [-M, M] m/s per axis on an object's velocity "
                        "after each robot-object impact")


def add_tether_options(p: argparse.ArgumentParser) -> None:
    """The tether environments' own options (``TetherEnv`` keywords beyond the shared ones)."""
    p.add_argument("--fidelity", choices=("kinematic", "reel", "force"), default="kinematic",
                   help="stations only: tether physics (kinematic: the thesis's Eq. 5; reel: slide joints reeled in; "
                        "force: saturating winch tension)")
    p.add_argument("--energy-penalty", type=float, default=0.0, metavar="C",
                   help="stations only: reward cost per J of winch work")
    p.add_argument("--pull-speed-mps", type=float, default=None, metavar="W",
                   help="stations only: the winches' real pulling speed (default: the station's)")
    p.add_argument("--max-active", type=int, default=None, metavar="K",
                   help="stations only: robots that may hold anchors at once (default: the station's k)")
    p.add_argument("--faults", default=None, metavar="SPEC",
                   help="stations only: faults drawn from each episode's seed, e.g. anchor_failures=1,tether_snaps=1,"
                        "robot_dropouts=1,winch_speed_error=0.1:0.3,window_s=10:150 (see impact_env.tether.faults)")


def transport_options(args: argparse.Namespace) -> dict[str, Any]:
    """``TransportEnv`` keywords from the parsed options."""
    return {"reward_mode": args.reward_mode, "fuel_penalty": args.fuel_penalty, "restitution": args.restitution,
            "thrust_noise": args.thrust_noise, "initial_position_noise_m": args.initial_position_noise_m,
            "impact_velocity_noise_mps": args.impact_velocity_noise_mps}


def check_world_options(args: argparse.Namespace, impact: bool, station: bool, what: str) -> None:
    """Options of a world that none of the command's scenarios or stations has are errors, not ignored:
    ``--fidelity`` for impact scenarios only, ``--thrust-noise`` for stations only, ``--reward-mode
    conjuncts`` for a station (``what`` names them in the message)."""
    from impact_env.errors import ImpactEnvError

    def flag(key: str) -> str:
        return "--" + key.replace("_", "-")

    if not station:
        given = [flag(k) for k, v in STATION_DEFAULTS.items() if getattr(args, k, v) != v]
        if given:
            raise ImpactEnvError(f"{', '.join(given)} appl{'ies' if len(given) == 1 else 'y'} to tether stations, not "
                                 f"to {what}")
    if not impact:
        given = [flag(k) for k, v in IMPACT_DEFAULTS.items() if getattr(args, k, v) != v]
        if given:
            raise ImpactEnvError(f"{', '.join(given)} appl{'ies' if len(given) == 1 else 'y'} to impact scenarios, "
                                 f"not to {what}")
        if getattr(args, "reward_mode", "dense") not in ("dense", "sparse"):
            raise ImpactEnvError(f"--reward-mode {args.reward_mode} applies to impact scenarios; a station takes "
                                 "dense or sparse")


def run_outputs(args: argparse.Namespace) -> None:
    """``run``'s outputs resolved and checked before any episode: ``--json`` and ``--plot`` (or
    ``summary.json`` and ``episode.png`` inside ``--out``) and ``--video``."""
    args.json = in_folder(args, "--json", "summary.json")
    args.plot = in_folder(args, "--plot", "episode.png")
    check_outputs({"--json": args.json, "--plot": args.plot, "--video": args.video}, {"--out": args.out})


def run_and_report(args: argparse.Namespace, env: Any, controller: Any, details: Callable[[Any], str]) -> list[Any]:
    """``run``'s episodes (``--episodes`` from ``--seed`` on): a line each with robustness, success,
    ``details(result)``, steps and time (none with ``--quiet``), and the first one's video if ``--video``;
    returns the results."""
    from impact_env.rollout import run_episodes as episodes

    results = []
    for res in episodes(env, controller, args.seed, args.episodes, record_first=bool(args.video)):
        results.append(res)
        if not args.quiet:
            print(f"episode {len(results)}/{args.episodes} seed={res.seed}: robustness={res.robustness:+.4f} m "
                  f"success={res.success} {details(res)} ({res.steps} steps, {res.wall_time_s:.2f} s)", flush=True)
    save_video(args.video, results[0], env)
    return results


def save_video(path: str | None, result: Any, env: Any) -> None:
    """The recorded frames of ``result`` (an ``EpisodeResult``) as an mp4 at the env's frame rate, if ``path``."""
    if path:
        from impact_env.rollout import write_video

        write_video(result.frames, path, fps=env.metadata["render_fps"])
        print(f"wrote {path}")


def save_summary(path: str | None, summary: dict[str, Any]) -> None:
    """``run``'s JSON summary, if ``path``, written atomically (its folder created)."""
    if path:
        write_atomic(path, json.dumps(summary, indent=2))
        print(f"wrote {path}")


def print_catalogue(first: str, names: Sequence[str], load: Callable[[str], Any],
                    columns: Sequence[tuple[str, str, Callable[[Any], Any]]]) -> None:
    """``impact-env scenarios``' table of one kind of shipped file: a row per name, its ``columns`` (title, format
    spec, value of the loaded file) between the name (headed ``first``) and the description."""
    # the pattern matches every string (the empty prefix at least)
    widths = [re.match(r"[<>^]?\d*", spec).group() for _, spec, _ in columns]  # type: ignore[union-attr]
    print(f"{first:<22}" + "".join(format(title, width) for (title, _, _), width in zip(columns, widths))
          + "  description")
    for name in names:
        loaded = load(name)
        print(f"{name:<22}" + "".join(format(value(loaded), spec) for _, spec, value in columns)
              + f"  {loaded.description}")
