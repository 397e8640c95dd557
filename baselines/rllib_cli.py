"""The options of ``impact-env train ... --engine rllib`` and its dispatch to :mod:`baselines.rllib_train`.

Nothing here imports Ray or the [rl] extra: ``impact-env`` loads it at start-up, also in a base install.
"""

from __future__ import annotations

import argparse
from typing import Any

ENGINES = ("sb3", "rllib")


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The training engine and RLlib's options, on the ``train`` subcommand."""
    group = p.add_argument_group("RLlib (--engine rllib)")
    group.add_argument("--engine", choices=ENGINES, default="sb3",
                       help="sb3: stable-baselines3 (default); rllib: RLlib's multi-agent PPO on the PettingZoo env")
    group.add_argument("--policies", choices=("shared", "independent"), default="independent",
                       help="--engine rllib: one policy per robot (default) or one shared by all")
    group.add_argument("--env-runners", type=int, default=1, metavar="N",
                       help="--engine rllib: sampling processes (Ray actors, 1 CPU each); 0 samples in the driver "
                            "(default 1); --n-envs is then the envs per runner")
    group.add_argument("--address", default=None, metavar="ADDR",
                       help="--engine rllib: train on this Ray cluster ('auto', HOST:PORT; default $RAY_ADDRESS, "
                            "else a private local instance)")
    group.add_argument("--ship-code", action="store_true",
                       help="--engine rllib: send this checkout's packages to the cluster's workers (Ray runtime env)")
    for flag, text in (("--resume", "continue the run saved in the run folder up to --timesteps"),
                       ("--trust-pickle", "--engine rllib --resume: load RLlib's pickled checkpoint (only your own)")):
        if not any(flag in a.option_strings for a in p._actions):  # the sb3 engine may define it already
            group.add_argument(flag, action="store_true", help=text)


def check_sb3_options(args: argparse.Namespace) -> None:
    """RLlib-only options given to the sb3 engine are an error, not silently ignored."""
    from impact_env.errors import ImpactEnvError

    given = [flag for flag, value, default in (("--policies", args.policies, "independent"),
                                                ("--env-runners", args.env_runners, 1),
                                                ("--address", args.address, None),
                                                ("--ship-code", args.ship_code, False)) if value != default]
    if given:
        raise ImpactEnvError(f"{', '.join(given)} appl{'ies' if len(given) == 1 else 'y'} to --engine rllib")


def run(args: argparse.Namespace, env_options: dict[str, Any]) -> int:
    """``impact-env train ppo SCENARIO --engine rllib``."""
    from baselines.rllib_train import RLlibTrainConfig, train_rllib
    from impact_env.errors import ImpactEnvError

    if args.algo != "ppo":
        raise ImpactEnvError(f"--engine rllib trains ppo, not {args.algo}")
    if args.multiagent:
        raise ImpactEnvError("--engine rllib is always multi-agent: choose --policies shared|independent instead "
                             "of --multiagent")
    options = {k: v for k, v in env_options.items() if k != "fidelity" and v is not None}
    config = RLlibTrainConfig(
        scenario=args.scenario, policies=args.policies, timesteps=args.timesteps, seed=args.seed,
        env_runners=args.env_runners, envs_per_runner=args.n_envs or 1, out=args.runs_dir, run_dir=args.out,
        env_options=options, eval_freq=args.eval_freq, hyperparams_file=args.hyperparams,
        max_minutes=args.max_minutes, address=args.address, ship_code=args.ship_code, resume=args.resume,
        trust_pickle=args.trust_pickle, verbose=not args.quiet)
    train_rllib(config)
    return 0
