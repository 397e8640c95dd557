"""``impact-env train`` (baselines/train.py), ``bench`` (baselines/bench.py), ``record`` (baselines/record.py),
``bc`` (baselines/bc.py), ``curves`` (baselines/curves.py)."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

# Nothing from the [rl] extra is imported here: `impact-env` loads this module at start-up, also in a base
# install (make demo), so stable-baselines3, yaml and minari are imported only by the command handlers.
from baselines import ALGOS, rllib_cli
from impact_env.envs.core import REWARD_MODES
from impact_env.sweep import add_engine_arguments, engine_config


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("train", help="train a PPO or SAC baseline on a scenario (stable-baselines3)")
    p.add_argument("algo", choices=ALGOS)
    p.add_argument("scenario", help="shipped name or path to a .toml file")
    p.add_argument("--timesteps", type=int, default=None, help="default: n_timesteps of the hyperparameter file")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--n-envs", type=int, default=None, help="parallel envs (subprocesses); default from the file")
    p.add_argument("--max-minutes", type=float, default=None,
                   help="wall-clock budget: stop before --timesteps when it runs out")
    p.add_argument("--out", default="runs", help="runs/<algo>_<scenario>_s<seed>/ gets model.zip, logs, checkpoints")
    p.add_argument("--hyperparams", default=None, help="an rl-zoo style YAML file (default baselines/hyperparams)")
    p.add_argument("--multiagent", action="store_true",
                   help="one shared policy for every robot on the PettingZoo env (parameter sharing)")
    p.add_argument("--eval-freq", type=int, default=20_000, help="env steps between evaluations")
    p.add_argument("--reward", choices=REWARD_MODES, default="dense", help="see impact_env.envs.core")
    p.add_argument("--fuel-penalty", type=float, default=0.0)
    p.add_argument("--restitution", type=float, default=None)
    p.add_argument("--thrust-noise", type=float, default=0.0)
    p.add_argument("--init-noise", type=float, default=0.0)
    p.add_argument("--fidelity", choices=("kinematic", "reel", "force"), default="kinematic",
                   help="tether stations only: the tether physics (see impact_env.tether_physics)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--verbose", type=int, default=0)
    rllib_cli.add_arguments(p)
    p.set_defaults(func=_run)

    p = subparsers.add_parser("bench", help="the same seeded episodes for several controllers: table and figure")
    p.add_argument("scenarios", nargs="?", default="corridor,obstacle_avoidance,throw_and_catch_exp",
                   help="comma-separated scenario names (default: all three)")
    p.add_argument("--controllers", default="expert,random,zero",
                   help="comma-separated: expert, random, zero, label:path/to/model.zip (stable-baselines3), "
                        "label:rllib:RUN_OR_CHECKPOINT (RLlib) ({scenario} in a path becomes each scenario's name)")
    p.add_argument("--episodes", type=int, default=10)
    p.add_argument("--out", default="bench", help="output folder (tables, CSV, figure)")
    p.add_argument("--thrust-noise", type=float, default=0.0, help="std of multiplicative thrust noise (0.05 = 5%%)")
    p.add_argument("--init-noise", type=float, default=0.0, help="objects start within this radius (m)")
    p.add_argument("--restitution", type=float, default=None, help="simulate with this restitution")
    p.add_argument("--trust-pickle", action="store_true",
                   help="also load pickled files of model folders (old vecnormalize.pkl, unknown pickled model "
                        "entries); a pickle can run any code: only for files you made yourself")
    p.add_argument("--fidelity", choices=("kinematic", "reel", "force"), default="kinematic",
                   help="tether stations only: the tether physics (see impact_env.tether_physics)")
    add_engine_arguments(p)
    p.set_defaults(func=_bench)

    p = subparsers.add_parser("convert-model", help="rewrite old model folders without pickles (vecnormalize.pkl "
                                                    "-> vecnormalize.json)")
    p.add_argument("folders", nargs="+", help="folders holding model.zip and vecnormalize.pkl")
    p.add_argument("--trust-pickle", action="store_true",
                   help="required: converting unpickles the old file, which can run code; only for your own files")
    p.set_defaults(func=_convert)

    p = subparsers.add_parser("record", help="record expert episodes as a Minari dataset")
    p.add_argument("scenario", help="shipped name or path to a .toml file")
    p.add_argument("--episodes", type=int, default=20)
    p.add_argument("--out", default="datasets", help="Minari datasets folder (MINARI_DATASETS_PATH)")
    p.add_argument("--plan", default=None, help="a saved plan; planned with the MILP if omitted")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--thrust-noise", type=float, default=0.0)
    p.add_argument("--init-noise", type=float, default=0.0)
    p.set_defaults(func=_record)

    p = subparsers.add_parser("bc", help="behaviour cloning from a recorded expert dataset (see `record`)")
    p.add_argument("scenario", help="shipped name or path to a .toml file")
    p.add_argument("--dataset", default="datasets", help="the folder `impact-env record --out` wrote")
    p.add_argument("--epochs", type=int, default=30)
    p.add_argument("--batch-size", type=int, default=256)
    p.add_argument("--lr", type=float, default=1e-3)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default="runs", help="runs/bc_<scenario>_s<seed>/ gets model.zip")
    p.set_defaults(func=_bc)

    p = subparsers.add_parser("curves", help="plot the evaluation curves of training runs")
    p.add_argument("runs", nargs="+", help="run folders written by `impact-env train`")
    p.add_argument("--out", default="curves.png")
    p.add_argument("--title", default="")
    p.add_argument("--labels", default=None, help="comma-separated legend labels, one per run")
    p.add_argument("--table", default=None, help="also write a markdown table of the runs to this file")
    p.set_defaults(func=_curves)


def _convert(args: argparse.Namespace) -> int:
    from baselines.model_files import TRUST_FLAG, convert_folder
    from impact_env.errors import UntrustedFileError

    if not args.trust_pickle:
        raise UntrustedFileError(f"convert-model unpickles the old vecnormalize.pkl, which can run code: pass "
                                 f"{TRUST_FLAG} if you made these folders yourself")
    for folder in args.folders:
        for line in convert_folder(Path(folder)):
            print(line)
    return 0


def _curves(args: argparse.Namespace) -> int:
    from baselines.curves import load_curve, plot_curves, training_table
    from impact_env.errors import ImpactEnvError

    curves = [load_curve(r) for r in args.runs]
    if args.labels is not None:
        labels = args.labels.split(",")
        if len(labels) != len(curves):
            raise ImpactEnvError(f"--labels has {len(labels)} labels for {len(curves)} runs")
        for c, label in zip(curves, labels):
            c.label = label
    plot_curves(curves, args.out, args.title)
    for c in curves:
        best = int(np.argmax(c.robustness.mean(axis=1)))
        print(f"{c.label}: {len(c.timesteps)} evaluations up to {c.timesteps[-1]} steps; last robustness "
              f"{c.robustness[-1].mean():+.3f}, best {c.robustness[best].mean():+.3f} at {c.timesteps[best]} steps")
    if args.table:
        Path(args.table).write_text(training_table(curves) + "\n")
        print(f"wrote {args.table}")
    print(f"wrote {args.out}")
    return 0


def _bc(args: argparse.Namespace) -> int:
    from baselines.bc import BCConfig, behaviour_clone

    run_dir = behaviour_clone(BCConfig(scenario=args.scenario, dataset_dir=args.dataset, epochs=args.epochs,
                                       batch_size=args.batch_size, learning_rate=args.lr, seed=args.seed,
                                       out=args.out))
    print(f"saved {run_dir / 'model.zip'}; fly it with: impact-env run {args.scenario} "
          f"--controller {run_dir / 'model.zip'}")
    return 0


def _record(args: argparse.Namespace) -> int:
    from baselines.record import dataset_id, mean_return, record

    options = {"thrust_noise": args.thrust_noise, "initial_position_noise_m": args.init_noise}
    ds = record(args.scenario, args.episodes, args.out, args.plan, options, args.seed)
    print(f"wrote Minari dataset {dataset_id(ds.spec.dataset_id.split('/')[1])} in {args.out}/: "
          f"{ds.total_episodes} episodes, {ds.total_steps} steps, mean return {mean_return(ds):+.3f}")
    return 0


def _bench(args: argparse.Namespace) -> int:
    from pathlib import Path

    from baselines.bench import markdown_table, parse_controllers, run_bench
    from impact_env.errors import ImpactEnvError

    if args.episodes < 1:
        raise ImpactEnvError(f"--episodes must be >= 1, got {args.episodes}")
    scenarios = args.scenarios.split(",")
    options = {"thrust_noise": args.thrust_noise, "initial_position_noise_m": args.init_noise}
    if args.restitution is not None:
        options["restitution"] = args.restitution
    from baselines.tether import is_station

    if any(is_station(s) for s in scenarios):
        options["fidelity"] = args.fidelity
    summary = run_bench(scenarios, parse_controllers(args.controllers, scenarios, args.trust_pickle), args.episodes,
                        Path(args.out), env_options=options, engine=engine_config(args))
    print(markdown_table(summary))
    print(f"wrote {args.out}/summary.md, summary.csv, episodes.csv, bench.png")
    return 0


def _run(args: argparse.Namespace) -> int:
    from baselines.train import TrainConfig, train

    options = {"reward_mode": args.reward, "fuel_penalty": args.fuel_penalty, "thrust_noise": args.thrust_noise,
               "initial_position_noise_m": args.init_noise}
    if args.restitution is not None:
        options["restitution"] = args.restitution
    from baselines.tether import is_station

    if is_station(args.scenario):
        options["fidelity"] = args.fidelity
    if args.engine == "rllib":
        return rllib_cli.run(args, options)
    rllib_cli.check_sb3_options(args)
    config = TrainConfig(algo=args.algo, scenario=args.scenario, timesteps=args.timesteps, seed=args.seed,
                         n_envs=args.n_envs, out=args.out, env_options=options, eval_freq=args.eval_freq,
                         multiagent=args.multiagent, progress_bar=not args.no_progress,
                         hyperparams_file=args.hyperparams, verbose=args.verbose,
                         max_minutes=args.max_minutes)
    run_dir = train(config)
    print(f"saved {run_dir / 'model.zip'}; fly it with: impact-env run {args.scenario} "
          f"--controller {run_dir / 'model.zip'}")
    return 0
