"""Train a residual policy on top of the expert with stable-baselines3's PPO: ``impact-env residual SCENARIO``.

    run_dir = train_residual(ResidualConfig("narrow_gap", plan="plan.json", timesteps=150_000))

One :class:`~baselines.residual.env.ResidualEnv` (the expert must act in the pymunk world, and one core is the
budget: no subprocesses), observations normalised (``VecNormalize``, its statistics saved as plain JSON), under
the issue's condition by default: 0.02 m/s post-impact velocity noise, 5 % thrust noise, 5 cm start noise
(:data:`TRAINING_NOISE`). The policy's last layer starts at zero, so its mean correction is zero and the first
rollouts fly the expert plus exploration noise only; ``action_penalty`` keeps an unhelpful correction small.

Resumable: every ``save_every`` env-steps the run folder gets ``model.zip`` (weights and optimiser state),
``vecnormalize.json`` and ``train.json`` (settings, steps trained, wall clock, and per chunk the training
episodes' success, robustness and mean |correction|); ``resume=True`` continues from there up to
``timesteps`` (``max_minutes`` stops a run early, at a chunk's end). Nothing is pickled
(:mod:`baselines.model_files`). Torch runs on one thread.
"""

from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from baselines.residual.env import DEFAULT_SCALE, ResidualEnv
from baselines.run_folder import check_run_folder, run_folder_path
from impact_env.config_checks import check_flag, check_instance, check_integer, check_number, check_text, check_widths
from impact_env.errors import ImpactEnvError
from impact_env.results_store import atomic_path, check_output_folder, write_atomic

__all__ = ["TRAINING_NOISE", "ResidualConfig", "build_expert", "train_residual"]

TRAINING_NOISE: dict[str, float] = {"impact_velocity_noise_mps": 0.02, "thrust_noise": 0.05,
                                    "initial_position_noise_m": 0.05}
"""The TransportEnv options the residual trains under by default (the issue's condition)."""
STACKS = ("paper", "+id", "+mission", "all")  # planners.expert.stacks.STACKS, checked without importing planners


@dataclass(frozen=True)
class ResidualConfig:
    """What :func:`train_residual` trains (see the module docstring)."""

    scenario: str
    """A shipped scenario name or a scenario file."""
    plan: str | None = None
    """The expert's offline plan (a ``Plan`` JSON file); None: planned with the MILP at the start."""
    stack: str = "all"
    """The expert's stack (:mod:`planners.expert.stacks`): ``all`` is ``ExpertConfig()``, the full expert."""
    scale: float = DEFAULT_SCALE
    """The largest correction as a fraction of each wrench limit, in (0, 2]."""
    action_penalty: float = 1e-4
    """Reward cost per step of mean(a**2) (a: the correction in [-1, 1]); an episode's robustness is in m."""
    env_options: dict[str, Any] = field(default_factory=lambda: dict(TRAINING_NOISE))
    """TransportEnv options of the training episodes (noise, reward mode)."""
    timesteps: int = 150_000
    """Env-steps to train (rounded up to whole rollouts of ``n_steps``)."""
    n_steps: int = 2048
    """Env-steps per PPO rollout."""
    batch_size: int = 256
    """Env-steps per gradient step."""
    n_epochs: int = 10
    """Passes over each rollout."""
    learning_rate: float = 1e-4
    """Adam's learning rate (constant, so a resumed run continues as it would have)."""
    gamma: float = 0.999
    """Discount: episodes are hundreds of steps and the reward is a robustness increment."""
    gae_lambda: float = 0.95
    """GAE's lambda."""
    log_std_init: float = -1.0
    """Initial log standard deviation of the correction's exploration (-1: 0.37, i.e. 7 % of a limit at scale 0.2)."""
    net_arch: tuple[int, ...] = (64, 64)
    """Hidden layer widths of the policy and value networks."""
    save_every: int = 20_480
    """Env-steps between saves of the run folder (whole rollouts)."""
    max_minutes: float | None = None
    """Stop at the first save after this many minutes of this call (None: run to ``timesteps``)."""
    seed: int = 0
    """Seed of PPO and of the training envs' episodes (env seeds from ``seed * 10**6 + 10**8``, apart from the
    benchmark's)."""
    out: str | None = None
    """The run folder; None: ``<runs_dir>/residual_<scenario>_s<seed>``."""
    runs_dir: str = "runs"
    """The parent of the default run folder."""
    resume: bool = False
    """Continue the run in the run folder (its settings must match)."""
    quiet: bool = False
    """No progress lines."""

    def __post_init__(self) -> None:
        check_text(self, "scenario", ImpactEnvError)
        check_text(self, "plan", ImpactEnvError, none="planned with the MILP")
        if self.stack not in STACKS:
            raise ImpactEnvError(f"ResidualConfig.stack must be one of {', '.join(STACKS)}, got {self.stack!r}")
        check_number(self, "scale", ImpactEnvError, low=0, high=2, low_open=True)
        check_number(self, "action_penalty", ImpactEnvError, low=0)
        check_instance(self, "env_options", ImpactEnvError, dict, what="a dict of TransportEnv options")
        for name in ("timesteps", "n_steps", "batch_size", "n_epochs", "save_every"):
            check_integer(self, name, ImpactEnvError, low=1)
        if self.batch_size > self.n_steps:
            raise ImpactEnvError(f"ResidualConfig.batch_size ({self.batch_size}) must be <= n_steps ({self.n_steps})")
        check_number(self, "learning_rate", ImpactEnvError, low=0, low_open=True)
        check_number(self, "gamma", ImpactEnvError, low=0, high=1)
        check_number(self, "gae_lambda", ImpactEnvError, low=0, high=1)
        check_number(self, "log_std_init", ImpactEnvError, low=-10, high=2)
        check_widths(self, "net_arch", ImpactEnvError)
        check_number(self, "max_minutes", ImpactEnvError, low=0, low_open=True, none="no wall-clock budget")
        check_integer(self, "seed", ImpactEnvError, low=0, high=99)
        check_run_folder(self, "residual_<scenario>_s<seed>")
        check_flag(self, "resume", ImpactEnvError)
        check_flag(self, "quiet", ImpactEnvError)

    def settings(self) -> dict[str, Any]:
        """The fields a resumed run must share with the run it continues (JSON types)."""
        skip = {"timesteps", "save_every", "max_minutes", "out", "runs_dir", "resume", "quiet"}
        return json.loads(json.dumps({f.name: getattr(self, f.name) for f in dataclasses.fields(self)
                                      if f.name not in skip}))


def build_expert(scenario: Any, plan: str | None, stack: str) -> Any:
    """The expert of ``stack`` for ``scenario``, flying the plan file ``plan`` (None: planned with the MILP)."""
    from planners.expert import Expert
    from planners.expert.stacks import stack_config
    from planners.plan import Plan

    return Expert(scenario, plan=Plan.load(plan) if plan else None, config=stack_config(stack))


def _start(config: ResidualConfig, run_dir: Path) -> dict[str, Any] | None:
    """The saved run's train.json to continue (None for a new run); refuses to overwrite or mix runs."""
    from baselines.model_files import read_train_json

    meta = read_train_json(run_dir)
    if not meta:
        if config.resume:
            raise ImpactEnvError(f"--resume: {run_dir} holds no residual run to continue (train without --resume)")
        return None
    if not config.resume:
        raise ImpactEnvError(f"{run_dir} holds a trained run already: continue it with --resume, or choose another "
                             "--out")
    if meta.get("method") != "residual":
        raise ImpactEnvError(f"--resume: {run_dir} holds no residual run (train.json method {meta.get('method')!r})")
    mine = config.settings()
    differ = sorted(k for k in mine if meta["settings"].get(k) != mine[k])
    if differ:
        raise ImpactEnvError(f"--resume: {run_dir} was trained with other settings ("
                             + "; ".join(f"{k} {meta['settings'].get(k)!r}, now {mine[k]!r}" for k in differ)
                             + "): resume with the same ones, or choose another --out")
    return meta


class _EpisodeLog:
    """Training episodes' outcomes, read from the env's infos after each step (an SB3 callback's job)."""

    def __init__(self) -> None:
        from stable_baselines3.common.callbacks import BaseCallback

        log = self

        class Callback(BaseCallback):
            def _on_step(self) -> bool:
                for info, done in zip(self.locals["infos"], self.locals["dones"]):
                    log.residual_sq.append(float(np.mean(np.square(info["residual"]))))
                    if done:
                        log.episodes.append((bool(info["is_success"]), float(info["robustness"])))
                return True

        self.callback = Callback()
        self.episodes: list[tuple[bool, float]] = []
        self.residual_sq: list[float] = []

    def row(self) -> dict[str, Any]:
        """This chunk's episodes (success rate, mean robustness) and RMS correction; then forget them."""
        ep = self.episodes
        out = {"episodes": len(ep), "success_rate": float(np.mean([s for s, _ in ep])) if ep else None,
               "robustness_mean": float(np.mean([r for _, r in ep])) if ep else None,
               "residual_rms": float(np.sqrt(np.mean(self.residual_sq))) if self.residual_sq else None}
        self.episodes, self.residual_sq = [], []
        return out


def train_residual(config: ResidualConfig) -> Path:
    """Train (or continue) a residual policy; returns the run folder (``model.zip``, ``vecnormalize.json``,
    ``train.json``), which :class:`~baselines.residual.env.ResidualController` flies."""
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        return _train(config)
    finally:
        torch.set_num_threads(threads)


def _train(config: ResidualConfig) -> Path:
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    from baselines.model_files import NORMALIZATION_FILE, read_normalization, set_obs_statistics
    from baselines.run_meta import scenario_fingerprint
    from impact_env.transport.gym_env import TransportEnv
    from impact_env.transport.scenario import load_scenario

    scenario = load_scenario(config.scenario)
    run_dir = run_folder_path(config.out, config.runs_dir, f"residual_{scenario.name}_s{config.seed}")
    check_output_folder(run_dir, "--out")
    meta = _start(config, run_dir)
    env = TransportEnv(scenario, **config.env_options)  # a bad option is an error before the plan is made
    expert = build_expert(scenario, config.plan, config.stack)
    residual_env = ResidualEnv(env, expert, config.scale, config.action_penalty)
    venv = VecNormalize(DummyVecEnv([lambda: residual_env]), gamma=config.gamma)
    model = PPO("MlpPolicy", venv, n_steps=config.n_steps, batch_size=config.batch_size, n_epochs=config.n_epochs,
                learning_rate=config.learning_rate, gamma=config.gamma, gae_lambda=config.gae_lambda,
                ent_coef=0.0, seed=config.seed, device="cpu", verbose=0,
                policy_kwargs={"net_arch": list(config.net_arch), "log_std_init": config.log_std_init})
    venv.seed(10**8 + config.seed * 10**6)  # after PPO's own seeding of the env, which would use ``seed``
    with torch.no_grad():
        for weight in model.policy.action_net.parameters():
            weight.zero_()  # the mean correction starts at zero: the expert flies
    chunks: list[dict[str, Any]] = []
    done, wall_s = 0, 0.0
    if meta is not None:
        model.set_parameters(str(run_dir / "model.zip"), exact_match=True, device="cpu")
        stats = read_normalization(run_dir / NORMALIZATION_FILE)
        set_obs_statistics(venv, stats.mean.copy(), stats.var.copy(), stats.count)
        raw = json.loads((run_dir / NORMALIZATION_FILE).read_text())["ret_rms"]
        venv.ret_rms.mean, venv.ret_rms.var = np.asarray(raw["mean"], float), np.asarray(raw["var"], float)
        venv.ret_rms.count = float(raw["count"])
        done, wall_s, chunks = int(meta["timesteps_trained"]), float(meta["wall_time_s"]), list(meta["chunks"])
        model.num_timesteps = done
        venv.seed(10**8 + config.seed * 10**6 + done)  # new episodes, not the first chunk's again
    chunk = max(1, round(config.save_every / config.n_steps)) * config.n_steps
    if not config.quiet:
        print(f"run folder: {run_dir}; residual PPO on {scenario.name} (expert stack {config.stack}, scale "
              f"{config.scale:g}) under {config.env_options}: {config.timesteps:,} env-steps"
              + (f", from {done:,} (resumed)" if done else ""), flush=True)
    log = _EpisodeLog()
    started = time.perf_counter()
    while done < config.timesteps:
        t0 = time.perf_counter()
        model.learn(total_timesteps=min(chunk, config.timesteps - done), callback=log.callback,
                    reset_num_timesteps=False, progress_bar=False)
        done = int(model.num_timesteps)
        wall_s += time.perf_counter() - t0
        row = {"env_steps": done, "wall_s": wall_s, **log.row()}
        chunks.append(row)
        _save(model, venv, run_dir, config, scenario, done, wall_s, chunks, scenario_fingerprint(scenario))
        if not config.quiet:
            rate = "-" if row["success_rate"] is None else f"{100 * row['success_rate']:.0f} %"
            rob = "-" if row["robustness_mean"] is None else f"{row['robustness_mean']:+.3f} m"
            print(f"  {done:,}/{config.timesteps:,} env-steps, {wall_s / 60:.1f} min: {row['episodes']} training "
                  f"episodes, success {rate}, robustness {rob}, RMS correction {row['residual_rms']:.3f}", flush=True)
        if (config.max_minutes is not None and done < config.timesteps
                and time.perf_counter() - started > 60 * config.max_minutes):
            if not config.quiet:
                print(f"  --max-minutes {config.max_minutes:g} reached: saved; continue with --resume", flush=True)
            break
    venv.close()
    return run_dir


def _save(model: Any, venv: Any, run_dir: Path, config: ResidualConfig, scenario: Any, done: int, wall_s: float,
          chunks: list[dict[str, Any]], fingerprint: str) -> None:
    from baselines.model_files import NORMALIZATION_FILE, save_normalization

    with atomic_path(run_dir / "model.zip") as tmp:  # a kill while saving keeps the last whole model
        model.save(tmp)
    save_normalization(venv, run_dir / NORMALIZATION_FILE)
    meta = {"algo": "ppo", "method": "residual", "normalized": True, "multiagent": False, "scenario": scenario.name,
            "scenario_fingerprint": fingerprint, "env_options": dict(config.env_options), "stack": config.stack,
            "scale": config.scale, "plan": config.plan, "settings": config.settings(), "timesteps": config.timesteps,
            "timesteps_trained": done, "wall_time_s": wall_s, "chunks": chunks}
    write_atomic(run_dir / "train.json", json.dumps(meta, indent=1))  # last: the folder is whole once it is there
