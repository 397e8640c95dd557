"""Train stable-baselines3 policies on the environments: ``impact-env train ALGO SCENARIO``.

Single agent (central control of all robots): the Gymnasium env in ``n_envs`` subprocesses, optional
``VecNormalize`` (observations and rewards), periodic evaluation on a separate env (best model kept; its
returns are the task's final STL robustness whatever the training reward; ``eval/evaluations.npz``),
checkpoints, TensorBoard logs, a progress bar; the model is saved in SB3's format (``model.zip``, plus
the normalisation statistics as plain JSON, ``vecnormalize.json``, when normalising: never a pickle, see
``baselines/model_files.py``; the periodic checkpoints in ``checkpoints/`` are SB3's own, pickles included,
for resuming training, and nothing in impact-env loads them). Multi-agent (``multiagent=True``): the
PettingZoo parallel env through SuperSuit's vector-env route, so ONE policy acts for every robot on its own
observation (parameter sharing). Environment options (reward mode, fuel penalty, noise) pass through.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from baselines import ALGOS, hyperparams
from baselines.model_files import LEGACY_NORMALIZATION_FILE, NORMALIZATION_FILE, save_normalization
from impact_env import GYM_IDS
from impact_env.errors import ImpactEnvError
from impact_env.scenario import load_scenario


@dataclass
class TrainConfig:
    algo: str
    scenario: str
    timesteps: int | None = None  # default: the hyperparameter file's n_timesteps
    seed: int = 0
    n_envs: int | None = None  # default: the file's n_envs
    out: str = "runs"
    env_options: dict[str, Any] = field(default_factory=dict)
    eval_freq: int = 20_000  # env steps between evaluations (summed over envs)
    eval_episodes: int = 5
    checkpoint_freq: int = 100_000
    multiagent: bool = False
    progress_bar: bool = True
    hyperparams_file: str | None = None
    verbose: int = 0
    max_minutes: float | None = None  # wall-clock budget: stop early (train.json records the steps reached)


def env_id_for(scenario: str) -> str:
    """The registered id of a shipped scenario (its hyperparameters are keyed by it)."""
    name = load_scenario(scenario).name
    for env_id, sc in GYM_IDS.items():
        if sc == name:
            return env_id
    return "impact_env/Corridor-v0"  # user scenarios take the corridor's hyperparameters


def train(config: TrainConfig) -> Path:
    """Train and save; returns the run directory (model.zip, vecnormalize.json, logs, checkpoints)."""
    from stable_baselines3 import PPO, SAC
    from stable_baselines3.common.callbacks import CallbackList, CheckpointCallback, EvalCallback
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import SubprocVecEnv, VecNormalize

    from impact_env.envs.transport import TransportEnv

    if config.algo not in ALGOS:
        raise ImpactEnvError(f"algorithm must be one of {ALGOS}, got {config.algo!r}")
    if config.max_minutes is not None and not config.max_minutes > 0:
        raise ImpactEnvError(f"max_minutes must be > 0, got {config.max_minutes!r}")
    scenario = load_scenario(config.scenario)
    env_id = env_id_for(config.scenario)
    entry = hyperparams.load(config.algo, env_id, config.hyperparams_file)
    n_envs = config.n_envs or int(entry.get("n_envs", 1))
    timesteps = int(config.timesteps or entry["n_timesteps"])
    run_dir = Path(config.out) / f"{config.algo}_{scenario.name}{'_ma' if config.multiagent else ''}_s{config.seed}"
    run_dir.mkdir(parents=True, exist_ok=True)
    env_kwargs = {"scenario": config.scenario, **config.env_options}

    if config.multiagent:
        if config.algo != "ppo":
            raise ImpactEnvError("parameter sharing over PettingZoo is supported with ppo")
        venv = _pettingzoo_vec_env(env_kwargs, n_envs)
    else:
        venv = make_vec_env(TransportEnv, n_envs=n_envs, seed=config.seed, env_kwargs=env_kwargs,
                            vec_env_cls=SubprocVecEnv if n_envs > 1 else None)
    # evaluation scores the task itself: under "dense" with no fuel penalty an episode's return is its final
    # STL robustness, whatever shaping the training env uses
    eval_kwargs = {**env_kwargs, "reward_mode": "dense", "fuel_penalty": 0.0}
    eval_env = make_vec_env(TransportEnv, n_envs=1, seed=config.seed + 10_000, env_kwargs=eval_kwargs)
    if entry.get("normalize"):
        venv = VecNormalize(venv, gamma=float(entry.get("gamma", 0.99)))
        eval_env = VecNormalize(eval_env, training=False, norm_reward=False, gamma=float(entry.get("gamma", 0.99)))
    cls = {"ppo": PPO, "sac": SAC}[config.algo]
    model = cls(entry.get("policy", "MlpPolicy"), venv, seed=config.seed, verbose=config.verbose,
                tensorboard_log=str(run_dir / "tb"), **hyperparams.algorithm_kwargs(entry))
    callbacks = [CheckpointCallback(max(1, config.checkpoint_freq // n_envs), str(run_dir / "checkpoints"),
                                    save_vecnormalize=True)]
    if not config.multiagent:
        # EvalCallback copies the training env's VecNormalize statistics to eval_env before evaluating
        callbacks.append(EvalCallback(eval_env, n_eval_episodes=config.eval_episodes,
                                              eval_freq=max(1, config.eval_freq // n_envs),
                                              best_model_save_path=str(run_dir / "best"),
                                              log_path=str(run_dir / "eval"), deterministic=True))
    if config.max_minutes is not None:
        callbacks.append(_wall_clock_budget(config.max_minutes * 60.0))
    start = time.perf_counter()
    model.learn(total_timesteps=timesteps, callback=CallbackList(callbacks), progress_bar=config.progress_bar)
    model.save(run_dir / "model.zip")
    if isinstance(venv, VecNormalize):
        save_normalization(venv, run_dir / NORMALIZATION_FILE)
    else:
        (run_dir / NORMALIZATION_FILE).unlink(missing_ok=True)  # a previous run's statistics are not this model's
    (run_dir / LEGACY_NORMALIZATION_FILE).unlink(missing_ok=True)  # a stale pickle must not sit beside the model
    (run_dir / "train.json").write_text(json.dumps({
        "algo": config.algo, "scenario": scenario.name, "env_id": env_id, "timesteps": timesteps,
        "timesteps_trained": int(model.num_timesteps), "max_minutes": config.max_minutes,
        "n_envs": n_envs, "seed": config.seed, "multiagent": config.multiagent, "env_options": config.env_options,
        "wall_time_s": time.perf_counter() - start}, indent=2))
    venv.close()
    eval_env.close()
    return run_dir


def _wall_clock_budget(seconds: float):
    """A callback that ends training once ``seconds`` of wall clock have passed (a compute budget)."""
    from stable_baselines3.common.callbacks import BaseCallback

    class WallClockBudget(BaseCallback):
        def _on_training_start(self) -> None:
            self._deadline = time.perf_counter() + seconds

        def _on_step(self) -> bool:
            return time.perf_counter() < self._deadline

    return WallClockBudget()


def _pettingzoo_vec_env(env_kwargs: dict[str, Any], n_envs: int):
    """PettingZoo parallel env -> SuperSuit vector env: every robot is one 'env' of a shared policy."""
    import supersuit as ss
    from stable_baselines3.common.vec_env import VecMonitor

    from impact_env.envs.transport_parallel import parallel_env

    par = parallel_env(**env_kwargs)
    venv = ss.pettingzoo_env_to_vec_env_v1(par)
    venv = ss.concat_vec_envs_v1(venv, n_envs, num_cpus=1, base_class="stable_baselines3")
    return VecMonitor(_SeedOnReset(venv))


def _SeedOnReset(venv):  # noqa: N802 - a class factory, so that importing this module needs no SB3
    """SuperSuit's SB3 wrapper forwards ``seed()`` to a Gymnasium 1.x vector env, which has no ``seed``:
    keep the seed and pass it to the next ``reset`` instead (the Gymnasium 1.x way)."""
    from stable_baselines3.common.vec_env import VecEnvWrapper

    class SeedOnReset(VecEnvWrapper):
        def __init__(self, inner) -> None:
            super().__init__(inner)
            self._seed: int | None = None

        def seed(self, seed: int | None = None):
            self._seed = seed
            return [seed] * self.num_envs

        def reset(self):
            if self._seed is None:
                return self.venv.reset()
            obs, self.venv.reset_infos = self.venv.venv.reset(seed=self._seed)
            self._seed = None
            return obs

        def step_wait(self):
            return self.venv.step_wait()

    return SeedOnReset(venv)
