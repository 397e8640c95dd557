"""Multi-agent PPO with RLlib on the PettingZoo env: ``impact-env train ppo SCENARIO --engine rllib``.

One policy per robot (``policies="independent"``) or one for all (``"shared"``, parameter sharing), trained by
RLlib's PPO (new API stack: RLModule, Learner, EnvRunner) on :mod:`baselines.rllib_env` with ``env_runners``
sampling processes (0 samples in the driver) of ``envs_per_runner`` envs each, on a private local Ray instance
or on the cluster at ``address``. The environment options (reward mode, fuel penalty, noise, restitution) are
the env's keywords, passed through.

Hyperparameters come from the same rl-baselines3-zoo file as stable-baselines3's PPO
(``baselines/hyperparams/ppo.yml``, or ``hyperparams_file``), translated by :func:`rllib_settings`: one update
per ``n_steps * n_envs`` env steps, minibatches of ``batch_size``, ``n_epochs`` passes, the same gamma, GAE
lambda, clip range, entropy and value coefficients, gradient clipping and learning-rate schedule, separate
policy and value networks of ``net_arch`` with tanh (SB3's default), and no KL penalty (SB3 has none).
``normalize: true`` becomes RLlib's per-agent ``MeanStdFilter`` on observations. The policy starts as SB3's
does: a state-independent log-std (``free_log_std``) at ``log_std_init``, orthogonal weights with gain sqrt(2)
in the hidden layers and 0.01 in the policy's output layer, zero biases (RLlib's defaults instead output the
log-std from the network, near std 1, and start the means far from zero; a first run with them had not touched
the object after 150k steps). What does not carry over: VecNormalize's reward scaling (RLlib has no such
connector; PPO standardises advantages either way).

Every ``eval_freq`` env steps the current policies fly ``eval_episodes`` seeded episodes of the central
Gymnasium env through the same controller as ``impact-env run --controller rllib:...``
(:mod:`baselines.rllib_policy`), scored by the task's final STL robustness (dense reward, no fuel penalty,
whatever the training reward), as the SB3 path's EvalCallback does; the results go to
``eval/evaluations.npz`` in SB3's format, so ``impact-env curves`` draws both. The run folder
(``<out>/rllib_ppo_<scenario>_<policies>_s<seed>/``) gets ``checkpoint/`` (RLlib's checkpoint, for resuming,
plus ``policy/``, the plain-data export that flies), ``checkpoints/step_<N>/`` every ``checkpoint_freq`` env
steps, ``best/policy/`` (the best evaluation), ``progress.csv`` (one row per iteration: steps, sampling and
iteration times) and ``train.json``. Resuming loads RLlib's pickles, so it needs ``trust_pickle``.
"""

from __future__ import annotations

import csv
import json
import math
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from baselines import hyperparams
from baselines.rllib_policy import FINAL_CHECKPOINT, POLICY_FOLDER, RLlibController, export_policy
from impact_env.config_checks import check_choice, check_flag, check_instance, check_integer, check_number, check_text
from impact_env.errors import EngineError, ImpactEnvError, UntrustedFileError

POLICY_MODES = ("shared", "independent")


@dataclass(frozen=True)
class RLlibTrainConfig:
    """What ``impact-env train ppo SCENARIO --engine rllib`` trains, and how (see the module docstring)."""

    scenario: str
    """A shipped impact scenario or a scenario file (tether stations train with stable-baselines3)."""
    policies: str = "independent"
    """One policy per robot (``independent``) or one for all (``shared``, parameter sharing)."""
    timesteps: int | None = None
    """Environment steps to train; None: the hyperparameter file's ``n_timesteps``."""
    seed: int = 0
    """Seed of RLlib's algorithm and of the evaluation episodes."""
    env_runners: int = 1
    """Sampling processes (Ray actors); 0 samples in the driver."""
    envs_per_runner: int = 1
    """Environments per env runner."""
    out: str = "runs"
    """The parent of the default run folder (``--runs-dir``)."""
    env_options: dict[str, Any] = field(default_factory=dict)
    """Keyword arguments of the environment (reward mode, fuel penalty, noise, restitution)."""
    eval_freq: int | None = None
    """Environment steps between evaluations; None: about five per run, at most every 20,000."""
    eval_episodes: int = 5
    """Episodes per evaluation."""
    checkpoint_freq: int = 100_000
    """Environment steps between checkpoints."""
    hyperparams_file: str | None = None
    """An rl-baselines3-zoo PPO hyperparameter file; None: ``baselines/hyperparams/ppo.yml``."""
    max_minutes: float | None = None
    """Wall-clock budget (min); None: no budget."""
    address: str | None = None
    """A Ray cluster; None: ``$RAY_ADDRESS``, else a private local instance."""
    ship_code: bool = False
    """Ship this checkout's packages to the Ray workers."""
    resume: bool = False
    """Continue the saved run in the run folder."""
    trust_pickle: bool = False
    """Trust RLlib's pickled checkpoint (resuming unpickles it)."""
    verbose: bool = True
    """Print a line per iteration."""
    run_dir: str | None = None
    """The run folder (``--out``); None: ``<out>/rllib_ppo_<scenario>_<policies>_s<seed>``."""

    def __post_init__(self) -> None:
        check_text(self, "scenario", ImpactEnvError)
        check_choice(self, "policies", ImpactEnvError, POLICY_MODES)
        check_integer(self, "timesteps", ImpactEnvError, low=1, none="the hyperparameter file's")
        check_integer(self, "seed", ImpactEnvError, low=0)
        check_integer(self, "env_runners", EngineError, low=0)
        check_integer(self, "envs_per_runner", EngineError, low=1)
        check_text(self, "out", ImpactEnvError)
        check_instance(self, "env_options", ImpactEnvError, dict, what="a dict of environment keywords")
        check_integer(self, "eval_freq", ImpactEnvError, low=1, none="about five per run")
        for name in ("eval_episodes", "checkpoint_freq"):
            check_integer(self, name, ImpactEnvError, low=1)
        check_text(self, "hyperparams_file", ImpactEnvError, none="the shipped file")
        check_number(self, "max_minutes", ImpactEnvError, low=0, low_open=True, none="no budget")
        check_text(self, "address", EngineError, none="$RAY_ADDRESS, else a private instance")
        for name in ("ship_code", "resume", "trust_pickle", "verbose"):
            check_flag(self, name, ImpactEnvError)
        check_text(self, "run_dir", ImpactEnvError, none="<out>/rllib_ppo_<scenario>_<policies>_s<seed>")


def rllib_settings(entry: dict[str, Any], timesteps: int) -> dict[str, Any]:
    """An rl-zoo PPO entry (as :func:`baselines.hyperparams.load` returns it) as RLlib PPO settings."""
    kwargs = entry.get("policy_kwargs", {}) or {}
    activation = getattr(kwargs.get("activation_fn"), "__name__", "Tanh").lower()
    if activation not in ("tanh", "relu"):
        raise hyperparams.HyperparameterError(f"activation_fn {activation!r}: RLlib runs use Tanh or ReLU")
    net_arch = kwargs.get("net_arch", [64, 64])
    if isinstance(net_arch, dict):  # dict(pi=[...], vf=[...]): RLlib's default module has one size for both
        net_arch = net_arch.get("pi", [64, 64])
    lr = entry.get("learning_rate", 3e-4)
    lr_start = float(lr(1.0)) if callable(lr) else float(lr)
    clip = entry.get("clip_range", 0.2)
    return {
        "train_batch_size_per_learner": int(entry.get("n_steps", 2048)) * int(entry.get("n_envs", 1)),
        "minibatch_size": int(entry.get("batch_size", 64)),
        "num_epochs": int(entry.get("n_epochs", 10)),
        "gamma": float(entry.get("gamma", 0.99)),
        "lambda_": float(entry.get("gae_lambda", 0.95)),
        "clip_param": float(clip(1.0)) if callable(clip) else float(clip),
        "entropy_coeff": float(entry.get("ent_coef", 0.0)),
        "vf_loss_coeff": float(entry.get("vf_coef", 0.5)),
        "grad_clip": float(entry.get("max_grad_norm", 0.5)),
        "grad_clip_by": "global_norm",
        "use_kl_loss": False,
        "vf_clip_param": float("inf"),  # SB3's clip_range_vf=None
        # lin_X: X decaying linearly to 0 at the end of the run, as SB3's schedule over its progress
        "lr": [[0, lr_start], [max(1, timesteps), 0.0]] if callable(lr) else lr_start,
        "model_config": {"fcnet_hiddens": [int(h) for h in net_arch], "fcnet_activation": activation,
                         "vf_share_layers": False, "free_log_std": True,
                         **({"fcnet_kernel_initializer": "orthogonal_",
                             "fcnet_kernel_initializer_kwargs": {"gain": math.sqrt(2)},
                             "fcnet_bias_initializer": "zeros_"} if kwargs.get("ortho_init", True) else {})},
        "normalize_observations": bool(entry.get("normalize", False)),
        "log_std_init": float(kwargs.get("log_std_init", 0.0)),
        "ortho_init": bool(kwargs.get("ortho_init", True)),
    }


def _check(config: RLlibTrainConfig) -> None:
    """What the config cannot check itself: the scenario is an impact scenario, not a tether station."""
    from baselines import tether

    if tether.is_station(config.scenario):
        raise ImpactEnvError("--engine rllib trains impact scenarios; tether stations train with the default "
                             "stable-baselines3 engine")


def run_folder(config: RLlibTrainConfig, scenario_name: str) -> Path:
    if config.run_dir:
        return Path(config.run_dir)
    return Path(config.out) / f"rllib_ppo_{scenario_name}_{config.policies}_s{config.seed}"


def build_algorithm(config: RLlibTrainConfig, settings: dict[str, Any], scenario: Any):
    """RLlib's PPO on the PettingZoo env of ``scenario`` (a loaded Scenario: it travels to the env runners whole,
    so a scenario file need not exist on other nodes) with ``settings`` (:func:`rllib_settings`)."""
    from ray.rllib.algorithms.ppo import PPOConfig
    from ray.rllib.core.rl_module.multi_rl_module import MultiRLModuleSpec
    from ray.rllib.core.rl_module.rl_module import RLModuleSpec

    from baselines import rllib_env

    settings = dict(settings)
    model_config = settings.pop("model_config")
    normalize = settings.pop("normalize_observations")
    log_std_init, ortho_init = settings.pop("log_std_init"), settings.pop("ortho_init")
    robots = [r.name for r in scenario.robots]
    policy_ids = robots if config.policies == "independent" else ["shared"]
    runners: dict[str, Any] = {"num_env_runners": config.env_runners,
                               "num_envs_per_env_runner": config.envs_per_runner,
                               "num_cpus_per_env_runner": 1, "rollout_fragment_length": "auto"}
    if normalize:
        runners["env_to_module_connector"] = rllib_env.observation_filter
    algo_config = (
        PPOConfig()
        .environment(rllib_env.register(), env_config={"scenario": scenario, **config.env_options})
        .env_runners(**runners)
        .multi_agent(policies=set(policy_ids),
                     policy_mapping_fn=(rllib_env.agent_to_policy if config.policies == "independent"
                                        else rllib_env.shared_policy))
        .rl_module(rl_module_spec=MultiRLModuleSpec(rl_module_specs={p: RLModuleSpec() for p in policy_ids}),
                   model_config=model_config)
        .training(**settings)
        .debugging(seed=config.seed, log_level="ERROR")
    )
    algo = algo_config.build_algo()
    _start_like_sb3(algo, log_std_init, ortho_init)
    return algo, model_config, normalize


def _start_like_sb3(algo: Any, log_std_init: float, ortho_init: bool) -> None:
    """Set every policy's log-std to ``log_std_init`` and (``ortho_init``) its output layer to SB3's orthogonal
    init with gain 0.01, on the learner, then send the weights to the env runners."""
    def init(learner: Any, _: Any = None) -> None:
        import torch

        for module_id in learner.module.keys():
            pi = learner.module[module_id].pi
            with torch.no_grad():
                pi.log_std.fill_(log_std_init)
                if ortho_init:
                    out = [m for m in pi.net.modules() if isinstance(m, torch.nn.Linear)][-1]
                    torch.nn.init.orthogonal_(out.weight, gain=0.01)
                    out.bias.zero_()

    algo.learner_group.foreach_learner(init)
    algo.env_runner_group.sync_weights(from_worker_or_learner_group=algo.learner_group, inference_only=True)


def _evaluate(scenario, folder: Path, eval_options: dict[str, Any], episodes: int, seed: int) -> tuple[list, list]:
    from impact_env.rollout import run_episode
    from impact_env.transport.gym_env import TransportEnv

    controller = RLlibController(scenario, folder)
    env = TransportEnv(scenario, **eval_options)
    results = [run_episode(env, controller, seed=10_000 + seed + k) for k in range(episodes)]
    env.close()
    return [r.robustness for r in results], [r.steps for r in results]


def train_rllib(config: RLlibTrainConfig) -> Path:
    """Train, checkpoint, evaluate and export; returns the run folder."""
    from baselines.train import default_eval_freq, env_id_for
    from impact_env.sweep import EngineConfig, connect_ray
    from impact_env.transport.pettingzoo_env import TransportParallelEnv
    from impact_env.transport.scenario import load_scenario

    _check(config)
    scenario = load_scenario(config.scenario)
    TransportParallelEnv(config.scenario, **config.env_options).close()  # a bad option fails here, once
    env_id = env_id_for(config.scenario)
    entry = hyperparams.load("ppo", env_id, config.hyperparams_file)
    timesteps = int(config.timesteps or entry["n_timesteps"])
    settings = rllib_settings(entry, timesteps)
    eval_freq = config.eval_freq or default_eval_freq(timesteps)
    run_dir = run_folder(config, scenario.name)
    final = run_dir / FINAL_CHECKPOINT
    if config.resume:
        if not final.is_dir():
            raise ImpactEnvError(f"--resume: {run_dir} has no RLlib checkpoint ({final} is missing)")
        if not config.trust_pickle:
            raise UntrustedFileError(f"resuming loads RLlib's checkpoint {final}, whose state files are pickles "
                                     "that can run code: pass --trust-pickle if you made this run yourself")
    run_dir.mkdir(parents=True, exist_ok=True)
    robots = [r.name for r in scenario.robots]
    agent_policies = {r: (r if config.policies == "independent" else "shared") for r in robots}
    eval_options = {**config.env_options, "reward_mode": "dense", "fuel_penalty": 0.0}
    say = print if config.verbose else (lambda *a, **k: None)

    try:
        import ray
        import ray.rllib  # noqa: F401
    except ImportError:
        raise EngineError("--engine rllib needs RLlib: pip install 'impact_env[ray]'") from None
    from baselines.rllib_notices import quiet_notices

    quiet_notices()
    owns_ray = connect_ray(EngineConfig("ray", address=config.address, ship_code=config.ship_code),
                           num_cpus=max(2, config.env_runners))
    start = time.perf_counter()
    try:
        algo, model_config, normalize = build_algorithm(config, settings, scenario)
        evals: dict[str, list] = {"timesteps": [], "results": [], "ep_lengths": []}
        if config.resume:
            algo.restore_from_path(str(final.resolve()))
            path = run_dir / "eval" / "evaluations.npz"
            if path.is_file():
                with np.load(path, allow_pickle=False) as old:
                    evals = {k: [row for row in np.asarray(old[k])] for k in evals}
        say(f"rllib ppo on {scenario.name}: {config.policies} policies {sorted(set(agent_policies.values()))}, "
            f"{config.env_runners} env runner(s) x {config.envs_per_runner} env(s), batch "
            f"{settings['train_batch_size_per_learner']} env steps, up to {timesteps} env steps"
            + (f" or {config.max_minutes:g} min" if config.max_minutes else ""), flush=True)
        best = max((float(np.mean(r)) for r in evals["results"]), default=-np.inf)  # the best evaluation so far

        def save(folder: Path) -> None:
            if folder.exists():
                shutil.rmtree(folder)
            algo.save_to_path(str(folder.resolve()))
            export_policy(algo, folder / POLICY_FOLDER, scenario, agent_policies, model_config, normalize,
                          config.env_options)

        def evaluate(steps: int) -> str:
            nonlocal best
            folder = run_dir / "eval" / POLICY_FOLDER
            export_policy(algo, folder, scenario, agent_policies, model_config, normalize, config.env_options)
            rho, lengths = _evaluate(scenario, folder, eval_options, config.eval_episodes, config.seed)
            for key, value in (("timesteps", steps), ("results", rho), ("ep_lengths", lengths)):
                evals[key].append(value)
            # numpy's stub lets **arrays fill savez's allow_pickle: bool, which these keys never name
            np.savez(run_dir / "eval" / "evaluations.npz", **{k: np.asarray(v) for k, v in evals.items()})  # type: ignore[arg-type]
            if np.mean(rho) > best:
                best = float(np.mean(rho))
                if (run_dir / "best").exists():
                    shutil.rmtree(run_dir / "best")
                shutil.copytree(folder, run_dir / "best" / POLICY_FOLDER)
            return f"; evaluation robustness {np.mean(rho):+.3f} (success {np.mean(np.asarray(rho) > 0):.0%})"

        progress_path = run_dir / "progress.csv"
        progress = open(progress_path, "a" if config.resume else "w", newline="")
        writer = csv.writer(progress)
        if not config.resume:
            writer.writerow(["iteration", "env_steps", "wall_s", "iteration_s", "sampling_s", "learning_s",
                             "sampled_env_steps", "sampling_env_steps_per_s"])
        steps = _lifetime_steps(algo)
        next_eval = (steps // eval_freq + 1) * eval_freq
        next_checkpoint = (steps // config.checkpoint_freq + 1) * config.checkpoint_freq

        def log_iteration(result: dict[str, Any], iteration: int, before: int, steps: int) -> str:
            """progress.csv's row, the evaluation and checkpoint when due, and the line to print."""
            nonlocal next_eval, next_checkpoint
            timers = result.get("timers", {})
            sampling = float(timers.get("env_runner_sampling_timer", float("nan")))
            sampled = steps - before
            number = result.get("training_iteration", iteration)
            writer.writerow([number, steps, f"{time.perf_counter() - start:.2f}",
                             f"{float(result.get('time_this_iter_s', 0)):.3f}", f"{sampling:.3f}",
                             f"{float(timers.get('learner_update_timer', float('nan'))):.3f}", sampled,
                             f"{sampled / sampling:.1f}" if sampling > 0 else ""])
            progress.flush()
            line = f"  iteration {number}: {steps} env steps"
            line += f", {sampled / sampling:.0f} env steps/s sampling" if sampling > 0 else ""
            if steps >= next_eval or steps >= timesteps:
                line += evaluate(steps)
                while next_eval <= steps:
                    next_eval += eval_freq
            if steps >= next_checkpoint:
                save(run_dir / "checkpoints" / f"step_{steps}")
                while next_checkpoint <= steps:
                    next_checkpoint += config.checkpoint_freq
            return line

        deadline = None if config.max_minutes is None else start + 60.0 * config.max_minutes
        iteration = 0
        interrupted = False
        try:
            while steps < timesteps and (deadline is None or time.perf_counter() < deadline):
                before = steps
                result = algo.train()
                iteration += 1
                steps = _lifetime_steps(algo, result)
                say(log_iteration(result, iteration, before, steps), flush=True)
        except KeyboardInterrupt:  # Ctrl-C: keep what was learned, say how to continue
            interrupted = True
        progress.close()
        if not evals["timesteps"] or evals["timesteps"][-1] != steps:  # always one evaluation at the end
            say(f"  final{evaluate(steps)[1:]}", flush=True)
        save(final)
        meta: dict[str, Any]
        meta = {"engine": "rllib", "algo": "ppo", "policies": config.policies, "agent_policies": agent_policies,
                "scenario": scenario.name, "env_id": env_id, "timesteps": timesteps, "timesteps_trained": steps,
                "max_minutes": config.max_minutes, "env_runners": config.env_runners,
                "envs_per_runner": config.envs_per_runner, "seed": config.seed, "multiagent": True,
                "env_options": config.env_options, "rllib_settings": {k: v for k, v in settings.items()},
                "ray_version": ray.__version__, "address": config.address, "interrupted": interrupted,
                "wall_time_s": time.perf_counter() - start}
        old = run_dir / "train.json"
        if config.resume and old.is_file():
            meta["wall_time_s"] += float(json.loads(old.read_text()).get("wall_time_s", 0.0))
        (run_dir / "train.json").write_text(json.dumps(meta, indent=2))
        algo.stop()
    finally:
        if owns_ray:
            ray.shutdown()
    say(f"saved {final}; fly it with: impact-env run {config.scenario} --controller rllib:{run_dir}", flush=True)
    if interrupted:
        print(f"interrupted at {steps} env steps; continue with the same command and --resume --trust-pickle",
              flush=True)
        raise KeyboardInterrupt
    return run_dir


def _lifetime_steps(algo: Any, result: dict[str, Any] | None = None) -> int:
    """Env steps sampled since the run began (restored with a checkpoint)."""
    if result is not None:
        value = result.get("env_runners", {}).get("num_env_steps_sampled_lifetime",
                                                  result.get("num_env_steps_sampled_lifetime"))
        if value is not None:
            return int(value)
    from ray.rllib.utils.metrics import ENV_RUNNER_RESULTS, NUM_ENV_STEPS_SAMPLED_LIFETIME

    value = algo.metrics.peek((ENV_RUNNER_RESULTS, NUM_ENV_STEPS_SAMPLED_LIFETIME), default=0)
    return int(value)
