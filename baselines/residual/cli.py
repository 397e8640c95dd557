"""``impact-env residual SCENARIO``: train a residual policy on top of the expert (:mod:`baselines.residual`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from impact_env.cli_options import add_quiet, add_run_folder, add_seed, add_transport_options, transport_options
from impact_env.transport.core import REWARD_MODES

STACKS = ("paper", "+id", "+mission", "all")


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``residual`` command (imports nothing from the [rl] extra: the handler does)."""
    p = subparsers.add_parser(
        "residual", help="a residual policy: PPO learns a correction added to the expert's command",
        description="Train a correction added to the expert's command each step (clip(u + scale * a, -1, 1)) with "
                    "stable-baselines3's PPO in the pymunk world, by default under 0.02 m/s post-impact velocity "
                    "noise, 5 % thrust noise and 5 cm start noise. One line per save; resumable (--resume). "
                    "Compare it with the expert alone on the same seeds: python -m benchmarks.residual.")
    p.add_argument("scenario", help="a shipped scenario name (impact-env scenarios) or a .toml file")
    p.add_argument("--plan", default=None, metavar="JSON", help="the expert's saved plan; planned with the MILP if "
                                                                "omitted")
    p.add_argument("--stack", default="all", choices=STACKS, help="the expert's stack (default all: ExpertConfig())")
    p.add_argument("--scale", type=float, default=0.2,
                   help="the largest correction as a fraction of each wrench limit, in (0, 2] (default 0.2)")
    p.add_argument("--action-penalty", type=float, default=1e-4, metavar="C",
                   help="reward cost per step of mean(a**2) of the correction a in [-1, 1] (default 1e-4)")
    p.add_argument("--timesteps", type=int, default=150_000, help="env-steps to train (default 150,000)")
    p.add_argument("--save-every", type=int, default=20_480, metavar="STEPS",
                   help="env-steps between saves of the run folder (default 20,480)")
    p.add_argument("--max-minutes", type=float, default=None,
                   help="stop at the first save after this many minutes (continue with --resume)")
    add_seed(p, "seed of PPO and of the training episodes (0-99)")
    add_run_folder(p, "model.zip, vecnormalize.json, train.json", "residual_<scenario>_s<seed>",
                   resume="continue the run in the run folder up to --timesteps")
    add_transport_options(p, REWARD_MODES)
    p.set_defaults(impact_velocity_noise_mps=0.02, thrust_noise=0.05, initial_position_noise_m=0.05)
    add_quiet(p, "no line per save")
    p.set_defaults(func=_residual)


def _residual(args: argparse.Namespace) -> int:
    from baselines.residual.train import ResidualConfig, train_residual

    options = {k: v for k, v in transport_options(args).items() if v not in (None, 0.0, "dense")}
    config = ResidualConfig(
        scenario=args.scenario, plan=args.plan, stack=args.stack, scale=args.scale, action_penalty=args.action_penalty,
        env_options=options, timesteps=args.timesteps, save_every=args.save_every, max_minutes=args.max_minutes,
        seed=args.seed, out=args.out, runs_dir=args.runs_dir, resume=args.resume, quiet=args.quiet)
    run_dir = train_residual(config)
    print(f"saved {Path(run_dir) / 'model.zip'}; compare it with the expert alone on the same seeds: python -m "
          f"benchmarks.residual --scenarios {args.scenario} --train-seeds {args.seed} "
          f"--runs-dir {Path(run_dir).parent}")
    return 0
