"""What every ``impact-env`` subcommand shares: the parser class, the environment options and ``run``'s outputs.

:class:`Parser` prints each option's default in ``--help`` and adds "did you mean" to argparse's errors for
a mistyped subcommand, choice or option. The environment options are named exactly as the environments'
keyword arguments, hyphenated (``--reward-mode`` is ``reward_mode=``, ``--initial-position-noise-m`` is
``initial_position_noise_m=``), so what works on the command line works in ``gym.make`` and back.
"""

from __future__ import annotations

import argparse
import json
import re
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from impact_env.catalogue import suggestion

# options renamed in 0.2.0 to match the environments' keywords
RENAMED = {"--reward": "--reward-mode", "--init-noise": "--initial-position-noise-m"}

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
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> None:  # noqa: D401 - argparse's hook
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

    def parse_args(self, args=None, namespace=None):  # type: ignore[override]
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


def run_and_report(args: argparse.Namespace, env: Any, controller: Any, details: Callable[[Any], str]) -> list[Any]:
    """``run``'s episodes (``--episodes`` from ``--seed`` on): a line each with robustness, success,
    ``details(result)``, steps and time, and the first one's video if ``--video``; returns the results."""
    from impact_env.rollout import run_episodes as episodes

    results = []
    for res in episodes(env, controller, args.seed, args.episodes, record_first=bool(args.video)):
        results.append(res)
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
    """``run``'s JSON summary, if ``path`` (its folder created)."""
    if path:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        Path(path).write_text(json.dumps(summary, indent=2))
        print(f"wrote {path}")


def print_catalogue(first: str, names: Sequence[str], load: Callable[[str], Any],
                    columns: Sequence[tuple[str, str, Callable[[Any], Any]]]) -> None:
    """``impact-env scenarios``' table of one kind of shipped file: a row per name, its ``columns`` (title, format
    spec, value of the loaded file) between the name (headed ``first``) and the description."""
    widths = [re.match(r"[<>^]?\d*", spec).group() for _, spec, _ in columns]
    print(f"{first:<22}" + "".join(format(title, width) for (title, _, _), width in zip(columns, widths))
          + "  description")
    for name in names:
        loaded = load(name)
        print(f"{name:<22}" + "".join(format(value(loaded), spec) for _, spec, value in columns)
              + f"  {loaded.description}")
