"""Train stable-baselines3 policies on the environments: ``impact-env train ALGO SCENARIO``.

Single agent (central control of all robots): the Gymnasium env in ``n_envs`` subprocesses, optional
``VecNormalize`` (observations and rewards), periodic evaluation on a separate env (best model kept; its
returns are the task's final STL robustness whatever the training reward; ``eval/evaluations.npz``),
checkpoints, TensorBoard logs with the task's own scalars (:mod:`baselines.train_callbacks`), progress as a bar
on a terminal and as plain lines otherwise; the model is saved in SB3's format (``model.zip``, plus the
normalisation statistics as plain JSON, ``vecnormalize.json``, when normalising: never a pickle, see
``baselines/model_files.py``; the periodic checkpoints in ``checkpoints/`` are SB3's own, pickles included, and
nothing in impact-env loads them). Multi-agent (``multiagent=True``): the PettingZoo parallel env through
SuperSuit's vector-env route, so ONE policy acts for every robot on its own observation (parameter sharing).
Environment options (reward mode, fuel penalty, noise) pass through.

The run folder is ``out`` (default ``runs/<algo>_<scenario>[_ma]_s<seed>``), printed when training starts.
Ctrl-C saves the model reached so far (``train.json`` says ``"interrupted": true``); ``resume=True``
(``--resume``) continues a saved run in its folder up to ``timesteps``: the weights and optimiser state, the
normalisation statistics, the step count and the evaluations are kept (SAC's replay buffer is not saved, so a
resumed SAC run refills it). Evaluations default to about five per run (at most every 20,000 steps) and one
at the end, so a short run has a learning curve too.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from baselines import ALGOS, hyperparams
from baselines.model_files import LEGACY_NORMALIZATION_FILE, NORMALIZATION_FILE, save_normalization
from baselines.run_folder import check_run_folder, run_folder_path
from impact_env import GYM_IDS
from impact_env.config_checks import (
    check_choice,
    check_flag,
    check_instance,
    check_integer,
    check_number,
    check_text,
)
from impact_env.errors import ImpactEnvError
from impact_env.results_store import atomic_path, check_output_folder, write_atomic
from impact_env.transport.scenario import load_scenario


@dataclass(frozen=True)
class TrainConfig:
    """What ``impact-env train ALGO SCENARIO`` trains, and how (see the module docstring)."""

    algo: str
    """The stable-baselines3 algorithm: ``ppo`` or ``sac``."""
    scenario: str
    """A shipped scenario or station name, or a scenario file."""
    timesteps: int | None = None
    """Environment steps to train (summed over the envs); None: the hyperparameter file's ``n_timesteps``."""
    seed: int = 0
    """Seed of the policy, the training envs and (plus 10,000) the evaluation env."""
    n_envs: int | None = None
    """Training envs (subprocesses when more than one); None: the hyperparameter file's ``n_envs``."""
    out: str | None = None
    """The run folder; None: ``<runs_dir>/<algo>_<scenario>[_ma]_s<seed>``."""
    runs_dir: str = "runs"
    """The parent of the default run folder."""
    env_options: dict[str, Any] = field(default_factory=dict)
    """Keyword arguments of the environment (reward mode, fuel penalty, noise, ...)."""
    eval_freq: int | None = None
    """Environment steps between evaluations (summed over the envs); None: about five per run."""
    eval_episodes: int = 5
    """Episodes per evaluation."""
    checkpoint_freq: int = 100_000
    """Environment steps between checkpoints (summed over the envs)."""
    multiagent: bool = False
    """Train one shared policy on the PettingZoo env (parameter sharing) instead of central control."""
    progress_bar: bool = True
    """A bar on a terminal, plain lines otherwise; False: neither."""
    hyperparams_file: str | None = None
    """An rl-baselines3-zoo hyperparameter file; None: ``baselines/hyperparams/<algo>.yml``."""
    verbose: int = 0
    """stable-baselines3's verbosity (0, 1 or 2)."""
    max_minutes: float | None = None
    """Wall-clock budget (min): stop early, ``train.json`` records the steps reached; None: no budget."""
    resume: bool = False
    """Continue the saved run in the run folder up to ``timesteps``."""

    def __post_init__(self) -> None:
        check_choice(self, "algo", ImpactEnvError, ALGOS)
        check_text(self, "scenario", ImpactEnvError)
        for name, none in (("timesteps", "the hyperparameter file's"), ("n_envs", "the hyperparameter file's"),
                           ("eval_freq", "about five per run")):
            check_integer(self, name, ImpactEnvError, low=1, none=none)
        check_integer(self, "seed", ImpactEnvError, low=0)
        check_run_folder(self, "<algo>_<scenario>[_ma]_s<seed>")
        check_instance(self, "env_options", ImpactEnvError, dict, what="a dict of environment keywords")
        for name in ("eval_episodes", "checkpoint_freq"):
            check_integer(self, name, ImpactEnvError, low=1)
        for name in ("multiagent", "progress_bar", "resume"):
            check_flag(self, name, ImpactEnvError)
        check_text(self, "hyperparams_file", ImpactEnvError, none="the shipped file")
        check_integer(self, "verbose", ImpactEnvError, low=0, high=2)
        check_number(self, "max_minutes", ImpactEnvError, low=0, low_open=True, none="no budget")


def load_world(name: str) -> Any:
    """The Scenario, or for a tether station the Station, that ``name`` (shipped name or file) describes."""
    from baselines import tether

    if tether.is_station(name):
        from impact_env.tether.station import load_station

        return load_station(name)
    return load_scenario(name)


def run_dir_for(config: TrainConfig) -> Path:
    """The run folder: ``config.out``, or ``<runs_dir>/<algo>_<scenario>[_ma]_s<seed>``."""
    if config.out is not None:
        return Path(config.out)
    name = load_world(config.scenario).name
    return run_folder_path(None, config.runs_dir,
                           f"{config.algo}_{name}{'_ma' if config.multiagent else ''}_s{config.seed}")


def effective_timesteps(algo: str, timesteps: int, n_envs: int, entry: dict[str, Any], multiagent: bool = False,
                        n_agents: int = 1) -> int:
    """The steps SB3 will really train for ``timesteps``: PPO collects whole rollouts (``n_steps`` per env)."""
    envs = n_envs * (n_agents if multiagent else 1)
    per_update = int(entry.get("n_steps", 2048)) * envs if algo == "ppo" else envs
    return -(-timesteps // per_update) * per_update


def default_eval_freq(total: int) -> int:
    """About five evaluations per run, at most every 20,000 steps (and one more at the end)."""
    return max(1, min(20_000, total // 5))


def env_id_for(scenario: str) -> str:
    """The registered id of a shipped scenario (its hyperparameters are keyed by it)."""
    from baselines import tether

    if tether.is_station(scenario):
        return tether.env_id_for_station(scenario)
    name = load_scenario(scenario).name
    for env_id, sc in GYM_IDS.items():
        if sc == name:
            return env_id
    return "impact_env/Corridor-v0"  # user scenarios take the corridor's hyperparameters


def train(config: TrainConfig) -> Path:
    """Train and save; returns the run directory (model.zip, vecnormalize.json, train.json, eval/, tb/, checkpoints/).

    Ctrl-C (KeyboardInterrupt) saves what was trained so far and re-raises it, so the caller can exit with 130.
    """
    from stable_baselines3 import PPO, SAC
    from stable_baselines3.common.callbacks import CallbackList, CheckpointCallback
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import SubprocVecEnv, VecNormalize

    from baselines import tether
    from baselines import train_callbacks as cb
    from impact_env.transport.gym_env import TransportEnv

    station = tether.is_station(config.scenario)
    env_cls: type  # TetherEnv or TransportEnv
    if station:  # a tether station: TetherEnv (MultiDiscrete commands), see baselines/tether.py
        from impact_env.tether.gym_env import TetherEnv
        from impact_env.tether.station import load_station

        if config.algo != "ppo" or config.multiagent:
            raise ImpactEnvError("tether stations train with ppo on the central env (their actions are discrete)")
        world = load_station(config.scenario)
        scenario_name, env_cls, n_robots = world.name, TetherEnv, world.n_robots
        robots = objects = frozenset[str]()  # the tether world has no impacts to count
        config = dataclasses.replace(config, env_options=tether.env_options(config.env_options, config.scenario))
    else:
        sc = load_scenario(config.scenario)
        scenario_name, env_cls, n_robots = sc.name, TransportEnv, len(sc.robots)
        robots, objects = frozenset(r.name for r in sc.robots), frozenset(o.name for o in sc.objects)
    env_id = env_id_for(config.scenario)
    entry = hyperparams.load(config.algo, env_id, config.hyperparams_file)
    n_envs = config.n_envs or int(entry.get("n_envs", 1))
    timesteps = int(config.timesteps or entry["n_timesteps"])
    run_dir = run_dir_for(config)
    previous = _previous_run(run_dir, config, scenario_name) if config.resume else None
    if not config.resume and (run_dir / "model.zip").is_file():
        print(f"note: {run_dir} holds a model already; it is overwritten (pass --resume to continue it)", flush=True)
    env_kwargs = {"station" if station else "scenario": config.scenario, **config.env_options}
    env_cls(**env_kwargs).close()  # a bad option is one clear error here, not one per worker process
    check_output_folder(run_dir, "--out")  # before any step is trained

    if config.multiagent:
        if config.algo != "ppo":
            raise ImpactEnvError("parameter sharing over PettingZoo is supported with ppo")
        venv = _pettingzoo_vec_env(env_kwargs, n_envs)
    else:
        venv = make_vec_env(functools.partial(_worker_env, env_cls), n_envs=n_envs, seed=config.seed,
                            env_kwargs=env_kwargs,
                            vec_env_cls=SubprocVecEnv if n_envs > 1 else None)
    # evaluation scores the task itself: under "dense" with no fuel penalty an episode's return is its final
    # STL robustness, whatever shaping the training env uses
    eval_kwargs = {**env_kwargs, "reward_mode": "dense", ("energy_penalty" if station else "fuel_penalty"): 0.0}
    eval_env = make_vec_env(env_cls, n_envs=1, seed=config.seed + 10_000, env_kwargs=eval_kwargs)
    if entry.get("normalize"):
        venv = VecNormalize(venv, gamma=float(entry.get("gamma", 0.99)))
        eval_env = VecNormalize(eval_env, training=False, norm_reward=False, gamma=float(entry.get("gamma", 0.99)))
    cls = {"ppo": PPO, "sac": SAC}[config.algo]
    model = cls(entry.get("policy", "MlpPolicy"), venv, seed=config.seed, verbose=config.verbose,
                tensorboard_log=str(run_dir / "tb"), **hyperparams.algorithm_kwargs(entry))
    done = 0
    if previous is not None:
        done = _restore(model, venv, run_dir, previous)
    total = effective_timesteps(config.algo, timesteps, n_envs, entry, config.multiagent, n_robots)
    if previous is not None and done >= timesteps:
        print(f"{run_dir} has trained {done:,} steps already (>= {timesteps:,}); nothing to do", flush=True)
        venv.close()
        eval_env.close()
        return run_dir
    if previous is not None:
        total = done + effective_timesteps(config.algo, timesteps - done, n_envs, entry, config.multiagent,
                                           n_robots)
    eval_freq = config.eval_freq or default_eval_freq(total)
    print(f"run folder: {run_dir}  (model.zip, train.json, eval/, checkpoints/; TensorBoard: tensorboard --logdir "
          f"{run_dir / 'tb'})", flush=True)
    print(f"training {config.algo.upper()} on {scenario_name}: {total:,} steps"
          + (f" (from {done:,}, resumed)" if done else "")
          + (f" ({timesteps - done:,} requested, rounded up to whole rollouts of {entry.get('n_steps', 2048)} steps "
             f"x {n_envs} envs)" if config.algo == "ppo" and total - done != timesteps - done else "")
          + f", {n_envs} env(s), evaluation every {eval_freq:,} steps", flush=True)

    count = cb.robot_object_impacts(robots, objects)
    callbacks = [CheckpointCallback(max(1, config.checkpoint_freq // n_envs), str(run_dir / "checkpoints"),
                                    save_vecnormalize=True), cb.task_metrics_callback(count)]
    if not config.multiagent:
        # EvalCallback copies the training env's VecNormalize statistics to eval_env before evaluating
        callbacks.append(cb.evaluation_callback(eval_env, count, previous=run_dir / "eval" / "evaluations.npz"
                                             if previous is not None else None,
                                             n_eval_episodes=config.eval_episodes,
                                             eval_freq=max(1, eval_freq // n_envs),
                                             best_model_save_path=str(run_dir / "best"),
                                             log_path=str(run_dir / "eval"), deterministic=True))
    if config.max_minutes is not None:
        callbacks.append(cb.wall_clock_budget(config.max_minutes * 60.0))
    if config.progress_bar:
        callbacks.append(cb.progress_callback(total))
    start = time.perf_counter()
    interrupted = False
    try:
        model.learn(total_timesteps=total - done, callback=CallbackList(callbacks), progress_bar=False,
                    reset_num_timesteps=previous is None)
    except KeyboardInterrupt:
        interrupted = True
    _save(model, venv, run_dir, config, scenario_name, env_id, timesteps, n_envs, interrupted,
          time.perf_counter() - start + (previous or {}).get("wall_time_s", 0.0))
    for env in (venv, eval_env):
        try:
            env.close()
        except Exception:  # noqa: BLE001 - after Ctrl-C the worker processes may be gone already
            pass
    if interrupted:
        print(f"\ninterrupted at step {model.num_timesteps:,}: saved {run_dir / 'model.zip'}; continue with "
              f"impact-env train {config.algo} {config.scenario} --out {run_dir} --resume", flush=True)
        raise KeyboardInterrupt
    return run_dir


def _worker_env(env_cls: type, **kwargs: Any):
    """The training env (``env_cls(**kwargs)``), made inside a SubprocVecEnv worker: a worker ignores Ctrl-C,
    which the main process handles (it saves the model); otherwise every worker would print a KeyboardInterrupt
    traceback."""
    import multiprocessing
    import signal

    if multiprocessing.parent_process() is not None:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    return env_cls(**kwargs)


def _previous_run(run_dir: Path, config: TrainConfig, scenario_name: str) -> dict[str, Any]:
    """The train.json of the run to resume, checked against this call's algorithm, scenario and options."""
    from baselines.model_files import read_train_json

    if not (run_dir / "model.zip").is_file():
        raise ImpactEnvError(f"--resume: {run_dir} has no model.zip to continue (train without --resume first)")
    meta = read_train_json(run_dir)
    wanted = {"algo": config.algo, "scenario": scenario_name, "multiagent": config.multiagent,
              "env_options": config.env_options}
    for key, value in wanted.items():
        if key in meta and meta[key] != value:
            raise ImpactEnvError(f"--resume: {run_dir} was trained with {key} = {meta[key]!r}, this call asks for "
                                 f"{value!r}; resume with the same options or train into another --out")
    return meta


def _restore(model: Any, venv: Any, run_dir: Path, meta: dict[str, Any]) -> int:
    """Load a saved run's weights (no pickle: SB3's set_parameters reads only the tensors), optimiser state,
    normalisation statistics and step count into a freshly built model; returns the steps already trained."""
    from stable_baselines3.common.vec_env import VecNormalize

    from baselines.model_files import read_normalization, set_obs_statistics

    model.set_parameters(str(run_dir / "model.zip"), exact_match=True, device=model.device)
    done = int(meta.get("timesteps_trained", 0))
    model.num_timesteps = done
    if isinstance(venv, VecNormalize) and (run_dir / NORMALIZATION_FILE).is_file():
        stats = read_normalization(run_dir / NORMALIZATION_FILE)
        set_obs_statistics(venv, stats.mean.copy(), stats.var.copy(), stats.count)
        raw = json.loads((run_dir / NORMALIZATION_FILE).read_text()).get("ret_rms", {})
        if raw:
            venv.ret_rms.mean = np.asarray(raw["mean"], dtype=float)
            venv.ret_rms.var = np.asarray(raw["var"], dtype=float)
            venv.ret_rms.count = float(raw["count"])
    return done


def _save(model: Any, venv: Any, run_dir: Path, config: TrainConfig, scenario_name: str, env_id: str,
          timesteps: int, n_envs: int, interrupted: bool, wall_time_s: float) -> None:
    from stable_baselines3.common.vec_env import VecNormalize

    from baselines.run_meta import scenario_fingerprint

    with atomic_path(run_dir / "model.zip") as tmp:  # a kill while saving keeps the last whole model
        model.save(tmp)
    if isinstance(venv, VecNormalize):
        save_normalization(venv, run_dir / NORMALIZATION_FILE)
    else:
        (run_dir / NORMALIZATION_FILE).unlink(missing_ok=True)  # a previous run's statistics are not this model's
    (run_dir / LEGACY_NORMALIZATION_FILE).unlink(missing_ok=True)  # a stale pickle must not sit beside the model
    write_atomic(run_dir / "train.json", json.dumps({
        "algo": config.algo, "scenario": scenario_name,
        "scenario_fingerprint": scenario_fingerprint(load_world(config.scenario)), "env_id": env_id,
        "timesteps": timesteps, "timesteps_trained": int(model.num_timesteps), "max_minutes": config.max_minutes,
        "n_envs": n_envs, "seed": config.seed, "multiagent": config.multiagent, "env_options": config.env_options,
        "normalized": isinstance(venv, VecNormalize),
        "interrupted": interrupted, "wall_time_s": wall_time_s}, indent=2))


def _pettingzoo_vec_env(env_kwargs: dict[str, Any], n_envs: int):
    """PettingZoo parallel env -> SuperSuit vector env: every robot is one 'env' of a shared policy."""
    import supersuit as ss
    from stable_baselines3.common.vec_env import VecMonitor

    from impact_env.transport.pettingzoo_env import parallel_env

    par = parallel_env(**env_kwargs)
    venv = ss.pettingzoo_env_to_vec_env_v1(par)
    venv = ss.concat_vec_envs_v1(venv, n_envs, num_cpus=1, base_class="stable_baselines3")
    return VecMonitor(_SeedOnReset(venv))


def _SeedOnReset(venv):  # noqa: N802 - a class factory, so that importing this module needs no SB3
    """SuperSuit's SB3 wrapper forwards ``seed()`` to a Gymnasium 1.x vector env, which has no ``seed``:
    keep the seed and pass it to the next ``reset`` instead (the Gymnasium 1.x way)."""
    from stable_baselines3.common.vec_env import VecEnvWrapper

    class SeedOnReset(VecEnvWrapper):
        def __init__(self, inner: Any) -> None:
            super().__init__(inner)
            self._seed: int | None = None
            self._supersuit: Any = inner  # SuperSuit's SB3 wrapper: its .venv is the Gymnasium vector env

        def seed(self, seed: int | None = None):
            self._seed = seed
            return [seed] * self.num_envs

        def reset(self):
            if self._seed is None:
                return self.venv.reset()
            obs, self._supersuit.reset_infos = self._supersuit.venv.reset(seed=self._seed)
            self._seed = None
            return obs

        def step_wait(self):
            return self.venv.step_wait()

    return SeedOnReset(venv)
