"""``impact-env train`` (baselines/train.py), ``bench`` (baselines/bench.py), ``record`` (baselines/record.py),
``dataset`` (baselines/task_dataset.py), ``bc`` (baselines/bc.py), ``dagger`` (baselines/dagger.py), ``bc-rl``
(baselines/batched/bc_rl.py), ``curves`` (baselines/curves.py), ``residual`` (baselines/residual/)."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

# Nothing from the [rl] extra is imported here: `impact-env` loads this module at start-up, also in a base
# install (make demo), so stable-baselines3, yaml and minari are imported only by the command handlers.
from baselines import ALGOS, rllib_cli
from baselines.residual import cli as residual_cli
from baselines.run_folder import run_folder_path
from impact_env.cli_options import (
    add_files,
    add_out,
    add_quiet,
    add_run_folder,
    add_seed,
    add_tether_options,
    add_transport_options,
    check_outputs,
    check_world_options,
    legacy_file_out,
    transport_options,
)
from impact_env.sweep import add_engine_arguments, engine_config
from impact_env.tether.cli import station_options
from impact_env.transport.core import REWARD_MODES


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("train", help="train a PPO or SAC baseline on a scenario (stable-baselines3)",
                              description="Train a PPO or SAC policy. Progress is a bar on a terminal and one line per "
                                          "rollout otherwise; Ctrl-C saves the model reached (continue with --resume).")
    p.add_argument("algo", choices=ALGOS, help="the algorithm")
    p.add_argument("scenario", help="a shipped scenario name (impact-env scenarios) or a .toml file")
    p.add_argument("--timesteps", type=int, default=None,
                   help="environment steps to train (default: n_timesteps of the hyperparameter file; PPO rounds up "
                        "to whole rollouts)")
    add_seed(p, "seed of the algorithm and the environments")
    p.add_argument("--n-envs", type=int, default=None,
                   help="parallel environments, in subprocesses when more than one (default: n_envs of the file)")
    p.add_argument("--max-minutes", type=float, default=None,
                   help="wall-clock budget: stop before --timesteps when it runs out (default: none)")
    add_run_folder(p, "model.zip, vecnormalize.json, train.json, eval/, tb/, checkpoints/",
                   "<algo>_<scenario>_s<seed>",
                   resume="continue the run saved in the run folder (after Ctrl-C, --max-minutes or a shorter "
                          "--timesteps) up to --timesteps")
    p.add_argument("--hyperparams", default=None, metavar="YAML",
                   help="an rl-baselines3-zoo style YAML file (default: baselines/hyperparams/<algo>.yml)")
    p.add_argument("--multiagent", action="store_true",
                   help="one shared policy for every robot on the PettingZoo env (parameter sharing)")
    p.add_argument("--eval-freq", type=int, default=None, metavar="STEPS",
                   help="environment steps between evaluations (default: a fifth of the run, at most 20,000; "
                        "there is always one at the end)")
    add_transport_options(p, REWARD_MODES)
    add_tether_options(p)
    add_quiet(p, "neither a progress bar nor progress lines", legacy_no_progress=True)
    p.add_argument("--verbose", type=int, default=0, help="stable-baselines3's verbosity (0, 1, 2)")
    rllib_cli.add_arguments(p)
    p.set_defaults(func=_run)

    p = subparsers.add_parser("bench", help="the same seeded episodes for several controllers: table and figure")
    p.add_argument("scenarios", nargs="?", default="corridor,obstacle_avoidance,throw_and_catch_exp",
                   help="comma-separated scenario names (default: all three)")
    p.add_argument("--controllers", default="expert,random,zero",
                   help="comma-separated: expert, random, zero, label:path/to/model.zip (stable-baselines3), "
                        "label:rllib:RUN_OR_CHECKPOINT (RLlib) ({scenario} in a path becomes each scenario's name)")
    p.add_argument("--episodes", type=int, default=10, help="seeded episodes per scenario and controller")
    add_seed(p, "seed of every scenario's and controller's first episode (episode k uses seed + k)")
    add_out(p, "summary.md, summary.csv, episodes.csv, bench.png and the expert's plans/", default="bench")
    add_transport_options(p, REWARD_MODES)
    add_tether_options(p)
    p.add_argument("--trust-pickle", action="store_true",
                   help="also load pickled files of model folders (old vecnormalize.pkl, unknown pickled model "
                        "entries); a pickle can run any code: only for files you made yourself")
    add_quiet(p, "no line per episode; only the table and the files written")
    add_engine_arguments(p)
    p.set_defaults(func=_bench)

    p = subparsers.add_parser("convert-model", help="rewrite old model folders without pickles (vecnormalize.pkl "
                                                    "-> vecnormalize.json)")
    p.add_argument("folders", nargs="+", help="folders holding model.zip and vecnormalize.pkl")
    p.add_argument("--trust-pickle", action="store_true",
                   help="required: converting unpickles the old file, which can run code; only for your own files")
    p.set_defaults(func=_convert)

    p = subparsers.add_parser("record", help="record expert episodes as a Minari dataset (with per-step infos)")
    p.add_argument("scenario", help="a shipped scenario name (impact-env scenarios) or a .toml file")
    p.add_argument("--episodes", type=int, default=20, help="episodes to record (seeds --seed, --seed + 1, ...)")
    add_out(p, "the Minari datasets folder (default: Minari's own, $MINARI_DATASETS_PATH or ~/.minari/datasets, so "
               "minari.load_dataset finds it without settings)")
    p.add_argument("--plan", default=None, metavar="JSON", help="a saved plan; planned with the MILP if omitted")
    add_seed(p)
    add_transport_options(p, REWARD_MODES)
    add_quiet(p, "no line per episode")
    p.set_defaults(func=_record)

    p = subparsers.add_parser("bc", help="behaviour cloning from a recorded expert dataset (see `record`)")
    p.add_argument("scenario", help="a shipped scenario name (impact-env scenarios) or a .toml file")
    p.add_argument("--dataset", default=None, metavar="DIR",
                   help="the Minari datasets folder `impact-env record --out` wrote (default: Minari's own)")
    p.add_argument("--epochs", type=int, default=30, help="passes over the demonstrations")
    p.add_argument("--batch-size", type=int, default=256, help="minibatch size")
    p.add_argument("--lr", type=float, default=1e-3, help="Adam learning rate")
    add_seed(p, "seed of the policy and the minibatches")
    add_run_folder(p, "model.zip, vecnormalize.json, train.json", "bc_<scenario>_s<seed>")
    add_quiet(p, "no line per epoch")
    p.set_defaults(func=_bc)

    p = subparsers.add_parser("dagger", help="DAgger: the expert labels the states the learner visits (rounds of BC)",
                              description="Round 0 clones the expert's own episodes (flown here, or --dataset); "
                                          "each further round flies the mixed policy, has the expert label every "
                                          "state visited (re-planning from it when it must: counted and timed), "
                                          "and refits on everything. One line per round; --resume continues.")
    p.add_argument("scenario", help="a shipped scenario name (impact-env scenarios) or a .toml file")
    p.add_argument("--rounds", type=int, default=4, help="rounds after round 0 (default 4)")
    p.add_argument("--initial-episodes", type=int, default=10, help="expert episodes of round 0 (default 10)")
    p.add_argument("--dataset", default=None, metavar="DIR",
                   help="round 0 from the Minari datasets folder `impact-env record --out` wrote instead")
    p.add_argument("--episodes-per-round", type=int, default=5, help="labelled episodes per round (default 5)")
    p.add_argument("--beta-decay", type=float, default=0.5,
                   help="round i flies the expert's action with probability beta_decay**i (default 0.5)")
    p.add_argument("--eval-episodes", type=int, default=10, help="episodes the learner flies alone after each fit")
    p.add_argument("--select-episodes", type=int, default=0,
                   help="validation episodes (seeds of their own) the learner flies after each fit; the run returns "
                        "the round with the most successes on them (default 0: the last round)")
    p.add_argument("--plan", default=None, metavar="JSON", help="the expert's saved plan; planned with the MILP if "
                                                                "omitted")
    p.add_argument("--max-replans", type=int, default=3, help="mission re-plans the expert may run per episode")
    p.add_argument("--epochs", type=int, default=30, help="passes over the data set in each fit")
    p.add_argument("--batch-size", type=int, default=256, help="minibatch size")
    p.add_argument("--lr", type=float, default=1e-3, help="Adam learning rate")
    add_seed(p, "seed of the fits, the per-step choices and the training episodes")
    add_run_folder(p, "model.zip, vecnormalize.json, train.json, dagger.json, rounds/", "dagger_<scenario>_s<seed>",
                   resume="continue the run in the run folder after its last round")
    add_transport_options(p, REWARD_MODES)
    add_quiet(p, "no line per round")
    p.set_defaults(func=_dagger)

    p = subparsers.add_parser("bc-rl", help="BC+RL: PPO from a BC or DAgger policy with a decaying behaviour-cloning "
                                            "loss, on the batched world",
                              description="Fine-tune the policy of --policy (impact-env bc or dagger) with "
                                          "stable-baselines3's PPO on the batched world, adding the expert pairs' "
                                          "negative log-likelihood to PPO's loss with a weight that halves every "
                                          "--bc-half-life env-steps; the value network learns alone for the first "
                                          "--critic-warmup-rollouts. The world is nominal unless noise options are "
                                          "given (a nominal world replays one episode in every env). Resumable: "
                                          "run the same command again.")
    p.add_argument("scenario", help="a shipped scenario name (impact-env scenarios) or a .toml file")
    p.add_argument("--policy", required=True, metavar="DIR",
                   help="the BC or DAgger run folder (its rounds/ are the expert pairs, else --dataset's)")
    p.add_argument("--dataset", default=None, metavar="DIR",
                   help="the Minari datasets folder of `impact-env record --out` (for a BC folder; default: Minari's)")
    add_run_folder(p, "model.zip, vecnormalize.json, train.json, curve.jsonl, updates.jsonl, result.json",
                   "bc_rl_<scenario>_s<seed>")
    add_seed(p, "seed of PPO, the BC minibatches and the envs")
    p.add_argument("--frames", type=int, default=1_000_000, help="env-step budget (default 1,000,000)")
    p.add_argument("--bc-weight", type=float, default=1.0, help="the BC loss's weight before it decays (default 1)")
    p.add_argument("--bc-half-life", type=int, default=1_000_000, metavar="FRAMES",
                   help="env-steps in which the BC weight halves (default 1,000,000; 0: constant)")
    p.add_argument("--critic-warmup-rollouts", type=int, default=1, metavar="N",
                   help="rollouts during which only the value network learns (default 1)")
    p.add_argument("--lr", type=float, default=1e-4, help="Adam learning rate (default 1e-4)")
    p.add_argument("--num-envs", type=int, default=256, help="envs of the batched world (default 256)")
    p.add_argument("--n-steps", type=int, default=None,
                   help="steps per env per rollout (default: the scenario's horizon, one whole episode)")
    p.add_argument("--batch-size", type=int, default=None,
                   help="env-steps per gradient step, a divisor of num-envs x n-steps (default: num-envs x the "
                        "largest divisor of n-steps up to 32)")
    p.add_argument("--normalize-advantage", action="store_true",
                   help="normalise each minibatch's advantages (SB3's default; off here: see BcRlConfig)")
    p.add_argument("--eval-episodes", type=int, default=50,
                   help="pymunk episodes flown by the BC policy before and by the result after (default 50)")
    add_transport_options(p, REWARD_MODES)
    add_quiet(p, "no line per checkpoint")
    p.set_defaults(func=_bc_rl)

    p = subparsers.add_parser("dataset", help="expert episodes on a family's kept generated tasks as Minari datasets "
                                              "(training and held-out)",
                              description="Fly the plans of the kept tasks in TASKS_DIR (impact-env filter --out) "
                                          "with the expert and store the episodes, padded to the family's "
                                          "goal-conditioned layout, as two Minari datasets: "
                                          "impact_env/generated_<family>/expert-v0 and .../heldout-v0.")
    p.add_argument("--family", required=True, help="the task family")
    p.add_argument("--tasks", required=True, metavar="TASKS_DIR", help="the folder impact-env filter --out wrote")
    p.add_argument("--episodes-per-task", type=int, default=1,
                   help="expert episodes per task (env seeds --seed, --seed + 1, ...)")
    p.add_argument("--heldout", type=float, default=0.2, help="share of tasks held out (default 0.2)")
    p.add_argument("--split-seed", type=int, default=0, help="seed of the held-out split (default 0)")
    p.add_argument("--max-tasks", type=int, default=None, help="use at most this many kept tasks (seed order)")
    add_out(p, "where the datasets go (default: Minari's own folder)")
    add_seed(p, "env seed of each task's first episode (episode k uses seed + k)")
    add_transport_options(p, REWARD_MODES)
    add_quiet(p, "no line per episode")
    p.set_defaults(func=_dataset)

    p = subparsers.add_parser("curves", help="plot the evaluation curves of training runs")
    p.add_argument("runs", nargs="+", help="run folders written by `impact-env train` (its --out)")
    add_out(p, "curves.png and, with --table, the table (default: the current folder)")
    add_files(p, plot="the figure (default: curves.png in --out)")
    p.add_argument("--title", default="", help="figure title")
    p.add_argument("--labels", default=None, help="comma-separated legend labels, one per run")
    p.add_argument("--table", default=None, metavar="MD", help="also write a markdown table of the runs to this file")
    p.set_defaults(func=_curves)

    residual_cli.register(subparsers)


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
    from impact_env.figures import png_path
    from impact_env.results_store import write_atomic

    legacy_file_out(args, "--plot", (".png",))
    args.plot = str(args.plot or Path(args.out or ".") / "curves.png")
    check_outputs({"--plot": args.plot, "--table": args.table}, {"--out": args.out})
    args.plot = str(png_path(args.plot))
    curves = [load_curve(r) for r in args.runs]
    if args.labels is not None:
        labels = args.labels.split(",")
        if len(labels) != len(curves):
            raise ImpactEnvError(f"--labels has {len(labels)} labels for {len(curves)} runs")
        for c, label in zip(curves, labels):
            c.label = label
    plot_curves(curves, args.plot, args.title)
    for c in curves:
        best = int(np.argmax(c.robustness.mean(axis=1)))
        print(f"{c.label}: {len(c.timesteps)} evaluations up to {c.timesteps[-1]} steps; last robustness "
              f"{c.robustness[-1].mean():+.3f}, best {c.robustness[best].mean():+.3f} at {c.timesteps[best]} steps")
    if args.table:
        write_atomic(args.table, training_table(curves) + "\n")
        print(f"wrote {args.table}")
    print(f"wrote {args.plot}")
    return 0


def _dataset(args: argparse.Namespace) -> int:
    from baselines.task_dataset import DatasetConfig, build_dataset

    if args.out is not None:
        check_outputs(folders={"--out": args.out})  # before any episode
    options = {k: v for k, v in transport_options(args).items() if v not in (None, 0.0, "dense")}
    config = DatasetConfig(episodes_per_task=args.episodes_per_task, heldout_share=args.heldout,
                           split_seed=args.split_seed, max_tasks=args.max_tasks, env_options=options or None,
                           seed=args.seed, quiet=args.quiet)
    train, heldout = build_dataset(args.family, args.tasks, config, out=args.out)
    for dataset in (train, heldout):
        if dataset is not None:
            print(f"wrote {dataset.spec.dataset_id}: {dataset.total_episodes} episodes, {dataset.total_steps} steps")
    return 0


def _bc(args: argparse.Namespace) -> int:
    from baselines.bc import BCConfig, behaviour_clone

    run_dir = behaviour_clone(BCConfig(scenario=args.scenario, dataset_dir=args.dataset, epochs=args.epochs,
                                       batch_size=args.batch_size, learning_rate=args.lr, seed=args.seed,
                                       out=args.out, runs_dir=args.runs_dir, quiet=args.quiet))
    print(f"saved {run_dir / 'model.zip'}; fly it with: impact-env run {args.scenario} "
          f"--controller {run_dir / 'model.zip'}")
    return 0


def _dagger(args: argparse.Namespace) -> int:
    from baselines.dagger import DAggerConfig, dagger

    options = {k: v for k, v in transport_options(args).items() if v not in (None, 0.0, "dense")}
    run_dir = dagger(DAggerConfig(
        scenario=args.scenario, rounds=args.rounds, initial_episodes=args.initial_episodes, dataset_dir=args.dataset,
        episodes_per_round=args.episodes_per_round, beta_decay=args.beta_decay, eval_episodes=args.eval_episodes,
        select_episodes=args.select_episodes,
        plan=args.plan, max_replans=args.max_replans, env_options=options or None, epochs=args.epochs,
        batch_size=args.batch_size, learning_rate=args.lr, seed=args.seed, out=args.out, runs_dir=args.runs_dir,
        resume=args.resume, quiet=args.quiet))
    print(f"saved {run_dir / 'model.zip'} (rounds in {run_dir / 'dagger.json'}); fly it with: impact-env run "
          f"{args.scenario} --controller {run_dir / 'model.zip'}")
    return 0


def _bc_rl(args: argparse.Namespace) -> int:
    from baselines.batched.bc_rl import BcRlConfig, run
    from impact_env.results_store import check_output_folder
    from impact_env.transport.scenario import load_scenario

    config = BcRlConfig(args.scenario, args.policy, dataset_dir=args.dataset, seed=args.seed, frames=args.frames,
                        bc_weight=args.bc_weight, bc_half_life_frames=args.bc_half_life or None,
                        critic_warmup_rollouts=args.critic_warmup_rollouts, lr=args.lr, num_envs=args.num_envs,
                        n_steps=args.n_steps, batch_size=args.batch_size,
                        normalize_advantage=args.normalize_advantage, eval_episodes=args.eval_episodes,
                        **transport_options(args))
    name = load_scenario(args.scenario).name
    out = run_folder_path(args.out, args.runs_dir, f"bc_rl_{name}_s{args.seed}")
    check_output_folder(out, "--out")  # before the world is built
    result = run(config, out, progress=not args.quiet)
    before, after = result["evaluation_init"]["pymunk"], result["evaluation"]["pymunk"]
    print(f"BC policy {100 * before['success_rate']:.0f} % ({before['robustness_mean']:+.3f} m), after "
          f"{result['env_steps']:,} env-steps {100 * after['success_rate']:.0f} % ({after['robustness_mean']:+.3f} m) "
          f"of {config.eval_episodes} pymunk episodes; saved {out / 'model.zip'}; fly it with: impact-env run "
          f"{args.scenario} --controller {out / 'model.zip'}")
    return 0


def _record(args: argparse.Namespace) -> int:
    from baselines.record import datasets_path, mean_return, record

    options = transport_options(args)
    ds = record(args.scenario, args.episodes, args.out, args.plan, options, args.seed, quiet=args.quiet)
    print(f"wrote Minari dataset {ds.spec.dataset_id} in {datasets_path(args.out)}: {ds.total_episodes} episodes, "
          f"{ds.total_steps} steps, mean return {mean_return(ds):+.3f}; load it with "
          f"minari.load_dataset({ds.spec.dataset_id!r})"
          + ("" if args.out is None else f" and MINARI_DATASETS_PATH={args.out}"))
    return 0


def _bench(args: argparse.Namespace) -> int:
    from pathlib import Path

    from baselines.bench import markdown_table, parse_controllers, run_bench
    from impact_env.errors import ImpactEnvError

    if args.episodes < 1:
        raise ImpactEnvError(f"--episodes must be >= 1, got {args.episodes}")
    if args.seed < 0:
        raise ImpactEnvError(f"--seed must be >= 0, got {args.seed}")
    scenarios = args.scenarios.split(",")
    from baselines.tether import is_station

    stations = [is_station(s) for s in scenarios]
    check_world_options(args, impact=not all(stations), station=any(stations),
                        what="these scenarios" if not any(stations) else "these stations")
    # every controller name is checked before any plan or episode (a typo after "expert" planned first in 0.2)
    controllers = parse_controllers(args.controllers, scenarios, args.trust_pickle)
    options = {**transport_options(args), **(station_options(args) if any(stations) else {})}
    summary = run_bench(scenarios, controllers, args.episodes, Path(args.out), env_options=options,
                        engine=engine_config(args), seed=args.seed, quiet=args.quiet)
    print(markdown_table(summary))
    print(f"wrote {args.out}/summary.md, summary.csv, episodes.csv, bench.png")
    return 0


def _run(args: argparse.Namespace) -> int:
    from baselines.tether import is_station
    from baselines.train import TrainConfig, train

    station = is_station(args.scenario)
    check_world_options(args, impact=not station, station=station,
                        what=f"station {args.scenario!r}" if station else "impact scenarios")
    options = station_options(args) if station else transport_options(args)
    # None: the file's own (no faults for --faults), as train.json records it
    for key in ("restitution", "pull_speed_mps", "max_active", "faults"):
        if options.get(key, 0) is None:
            del options[key]
    if args.engine == "rllib":
        try:
            return rllib_cli.run(args, options)
        except KeyboardInterrupt:  # the run was saved, and the way to resume printed
            return 130
    rllib_cli.check_sb3_options(args)
    config = TrainConfig(algo=args.algo, scenario=args.scenario, timesteps=args.timesteps, seed=args.seed,
                         n_envs=args.n_envs, out=args.out, runs_dir=args.runs_dir, env_options=options,
                         eval_freq=args.eval_freq, multiagent=args.multiagent, progress_bar=not args.quiet,
                         hyperparams_file=args.hyperparams, verbose=args.verbose, max_minutes=args.max_minutes,
                         resume=args.resume)
    try:
        run_dir = train(config)
    except KeyboardInterrupt:  # train() saved the model and said so
        return 130
    print(f"saved {run_dir / 'model.zip'}; fly it with: impact-env run {args.scenario} "
          f"--controller {run_dir / 'model.zip'}")
    return 0
