"""stable-baselines3's PPO on the batched impact world (centralised: one policy for every robot's action),
trained through :class:`~impact_env.transport.batched.sb3_vec_env.TransportSB3VecEnv`, resumable.

    python -m baselines.batched.sb3_ppo corridor --seed 0 --frames 10000000 --out runs/sb3_ppo_corridor_s0

One run is one folder: ``model.zip``, ``vecnormalize.json`` and ``train.json`` (the checkpoint, written every
``--checkpoint-frames`` env-steps, each file atomically, in the package's pickle-free form that ``impact-env
bench`` reads as a controller), ``state.json`` (env-steps and wall clock at that checkpoint, written last),
``curve.jsonl`` (one line per PPO rollout: env-steps, wall clock, the mean reward per env-step, and the
finished training episodes' mean return, success rate and final robustness) and, when the budget is spent,
``result.json`` (the configuration, the budget, the wall clock and the final deterministic evaluation). A
killed run started again with the same arguments resumes from its last checkpoint: the curve lines after it
are dropped and the episodes in flight restart (so a resumed run is not bit-identical to an uninterrupted
one). A finished run is not trained again.

The hyperparameters are :class:`Sb3PpoConfig`'s, the same for every scenario: the package's PPO baseline
(``baselines/hyperparams/ppo.yml``: ``log_std_init`` -0.5, gamma 0.999, observation and reward normalisation)
made for a wall-clock budget on a small CPU: a wide batch with short rollouts (512 envs x 16 steps; the
eager world costs about the same per call at 64 or 512 envs, so wide is cheap per env-step), a [64, 64] MLP
and 4 epochs (the update is the other half of the time), and a constant learning rate (a linear schedule would
restart at every chunk of ``learn``). The final evaluation flies the deterministic policy on the batched world
and on the pymunk Gymnasium env, ``eval_episodes`` seeded episodes each with the training's noise, as
:mod:`baselines.batched.marl` does.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import torch

from impact_env.config_checks import (
    check_choice,
    check_flag,
    check_integer,
    check_number,
    check_text,
    check_widths,
    fail,
)
from impact_env.errors import ImpactEnvError
from impact_env.results_store import atomic_path, write_atomic
from impact_env.transport.core import REWARD_MODES

EVAL_FIRST_SEED = 1_000_000


class WorldRun(Protocol):
    """What the helpers below read of a run's config (:class:`Sb3PpoConfig`, and
    :class:`~baselines.batched.bc_rl.BcRlConfig`, which trains through them too)."""

    @property
    def scenario(self) -> str: ...

    @property
    def seed(self) -> int: ...

    @property
    def frames(self) -> int: ...

    @property
    def num_envs(self) -> int: ...

    @property
    def compile(self) -> bool: ...

    def world_options(self) -> dict[str, Any]: ...


def check_ppo_settings(cfg: Any, num_envs: int) -> None:
    """The checks of the PPO settings :class:`Sb3PpoConfig` shares with the family trainer
    (:class:`~baselines.batched.family_ppo.FamilyPpoConfig`): seed, budget, rollout, optimiser, network, noise
    and reward. ``num_envs``: the batch, whose rollout the minibatches must divide."""
    name_of = type(cfg).__name__
    check_integer(cfg, "seed", ImpactEnvError, low=0)
    for name in ("frames", "n_steps", "batch_size", "n_epochs", "checkpoint_frames", "threads"):
        check_integer(cfg, name, ImpactEnvError, low=1)
    for name in ("lr", "clip_range"):
        check_number(cfg, name, ImpactEnvError, low=0, low_open=True)
    check_number(cfg, "gamma", ImpactEnvError, low=0, high=1, low_open=True)
    check_number(cfg, "gae_lambda", ImpactEnvError, low=0, high=1)
    check_number(cfg, "ent_coef", ImpactEnvError, low=0)
    check_number(cfg, "log_std_init", ImpactEnvError)
    for name in ("thrust_noise", "initial_position_noise_m"):
        check_number(cfg, name, ImpactEnvError, low=0)
    check_choice(cfg, "reward_mode", ImpactEnvError, REWARD_MODES)
    check_widths(cfg, "hidden", ImpactEnvError)
    if (num_envs * cfg.n_steps) % cfg.batch_size:
        fail(f"{name_of}.batch_size", cfg.batch_size, f"a divisor of num_envs x n_steps ({num_envs} x "
             f"{cfg.n_steps} = {num_envs * cfg.n_steps})", ImpactEnvError)


@dataclass(frozen=True)
class Sb3PpoConfig:
    """One SB3 PPO run on the batched world."""

    scenario: str
    """A shipped scenario name or a scenario TOML path."""
    seed: int = 0
    """Seeds the networks (SB3's ``seed``) and the envs (env i of the batch starts at seed * 100,000 + i)."""
    frames: int = 10_000_000
    """Env-step budget: one env-step is one control period of one env, all its robots included."""
    num_envs: int = 512
    """Envs of the batch."""
    n_steps: int = 16
    """Steps of each env per rollout (a rollout is num_envs x n_steps env-steps)."""
    batch_size: int = 2048
    """Env-steps per gradient step."""
    n_epochs: int = 4
    """Passes over each rollout."""
    lr: float = 3e-4
    """Adam learning rate (constant)."""
    gamma: float = 0.999
    """Discount."""
    gae_lambda: float = 0.95
    """GAE lambda."""
    clip_range: float = 0.2
    """PPO's clip range."""
    ent_coef: float = 0.0
    """Entropy bonus."""
    hidden: tuple[int, ...] = (64, 64)
    """Hidden layer widths of the policy and value networks."""
    log_std_init: float = -0.5
    """Initial log standard deviation of the Gaussian policy."""
    thrust_noise: float = 0.05
    """Multiplicative thrust noise (the expert-vs-learned benchmark's condition)."""
    initial_position_noise_m: float = 0.05
    """Objects start within this radius (m)."""
    reward_mode: str = "dense"
    """The world's reward (``dense``, ``sparse``, ``conjuncts``)."""
    compile: bool = False
    """Run the world's torch.compile kernels (a compilation of minutes per scenario on 2 cores)."""
    checkpoint_frames: int = 131_072
    """Env-steps between checkpoints (rounded up to whole rollouts)."""
    eval_episodes: int = 50
    """Episodes of the final deterministic evaluation, per world (the pymunk half costs about as much as a third
    of a 500k-step training on the shared 2-core machine)."""
    threads: int = 1
    """torch threads of the run."""

    def __post_init__(self) -> None:
        check_text(self, "scenario", ImpactEnvError)
        for name in ("num_envs", "eval_episodes"):
            check_integer(self, name, ImpactEnvError, low=1)
        check_flag(self, "compile", ImpactEnvError)
        check_ppo_settings(self, self.num_envs)

    @property
    def rollout_frames(self) -> int:
        return self.num_envs * self.n_steps

    @property
    def chunk_frames(self) -> int:
        """Env-steps between checkpoints: whole rollouts."""
        return -(-self.checkpoint_frames // self.rollout_frames) * self.rollout_frames

    def world_options(self) -> dict[str, Any]:
        return {"thrust_noise": self.thrust_noise, "initial_position_noise_m": self.initial_position_noise_m,
                "reward_mode": self.reward_mode}


def make_venv(cfg: WorldRun):
    from stable_baselines3.common.vec_env import VecMonitor

    from impact_env.transport.batched.sb3_vec_env import TransportSB3VecEnv

    venv = TransportSB3VecEnv(cfg.scenario, cfg.num_envs, compile=cfg.compile, **cfg.world_options())
    venv.seed(cfg.seed * 100_000)
    return VecMonitor(venv)


def curve_callback(curve: Path, wall_before: float):
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.vec_env import VecNormalize

    class CurveLogger(BaseCallback):
        """One line of ``curve`` per rollout, from the episodes that ended in it."""

        def __init__(self) -> None:
            super().__init__()
            self.t0 = time.perf_counter()
            self.returns: list[float] = []
            self.robustness: list[float] = []
            self.reward_sum, self.reward_count = 0.0, 0

        def wall_s(self) -> float:
            return wall_before + time.perf_counter() - self.t0

        def _on_step(self) -> bool:
            env = self.training_env
            if not isinstance(env, VecNormalize):
                raise ImpactEnvError(f"the curve reads the world's reward from VecNormalize, got {type(env).__name__}")
            raw = env.get_original_reward()  # the world's reward of this step
            self.reward_sum += float(raw.sum())
            self.reward_count += raw.size
            dones = self.locals["dones"]
            if dones.any():
                infos = self.locals["infos"]
                for i in np.flatnonzero(dones):
                    self.returns.append(float(infos[i]["episode"]["r"]))
                    self.robustness.append(float(infos[i]["robustness"]))
            return True

        def _on_rollout_end(self) -> None:
            n = len(self.returns)
            rob = np.array(self.robustness)
            row = {"frames": int(self.num_timesteps), "wall_s": round(self.wall_s(), 2), "episodes": n,
                   "return_mean": float(np.mean(self.returns)) if n else None,
                   "success_rate": float((rob > 0).mean()) if n else None,
                   "robustness_mean": float(rob.mean()) if n else None,
                   # every env-step's reward: a curve even where no episode ends within a rollout (long horizons)
                   "reward_per_step": self.reward_sum / max(self.reward_count, 1)}
            with curve.open("a", encoding="utf-8") as f:
                f.write(json.dumps(row) + "\n")
            self.returns.clear()
            self.robustness.clear()
            self.reward_sum, self.reward_count = 0.0, 0

    return CurveLogger()


def truncate_curve(curve: Path, frames: int) -> None:
    if not curve.exists():
        return
    rows = [line for line in curve.read_text(encoding="utf-8").splitlines()
            if line.strip() and json.loads(line)["frames"] <= frames]
    write_atomic(curve, "".join(r + "\n" for r in rows))


def save_checkpoint(model, venv, cfg: WorldRun, out: Path, wall_s: float,
                    trainer: str = "baselines.batched.sb3_ppo (batched world)",
                    meta: dict[str, Any] | None = None) -> None:
    """model.zip, vecnormalize.json and train.json (the package's pickle-free model folder, which ``impact-env
    bench`` reads as a controller; ``meta`` adds keys to train.json), then state.json, each atomically:
    state.json names the step count of the files beside it only once they are all written."""
    from baselines.model_files import save_normalization
    from baselines.run_meta import scenario_fingerprint
    from impact_env.transport.scenario import load_scenario

    with atomic_path(out / "model.zip") as tmp:
        model.save(tmp)
    with atomic_path(out / "vecnormalize.json") as tmp:
        save_normalization(venv, tmp)
    scenario = load_scenario(cfg.scenario)
    write_atomic(out / "train.json", json.dumps({
        "algo": "ppo", "scenario": scenario.name, "scenario_fingerprint": scenario_fingerprint(scenario),
        "env_id": None, "timesteps": cfg.frames, "timesteps_trained": int(model.num_timesteps), "n_envs": cfg.num_envs,
        "seed": cfg.seed, "multiagent": False, "env_options": cfg.world_options(), "interrupted": False,
        "wall_time_s": round(wall_s, 2), "trainer": trainer} | (meta or {}), indent=2))
    write_atomic(out / "state.json", json.dumps({"frames": int(model.num_timesteps), "wall_s": round(wall_s, 2)}))


def restore(model, venv, out: Path) -> None:
    """The checkpoint's weights and optimiser state (SB3's set_parameters reads tensors only, no pickle) and the
    normalisation statistics, into a freshly built model."""
    from baselines.model_files import NORMALIZATION_FILE, read_normalization

    model.set_parameters(str(out / "model.zip"), exact_match=True, device=model.device)
    stats = read_normalization(out / NORMALIZATION_FILE)
    venv.obs_rms.mean, venv.obs_rms.var, venv.obs_rms.count = stats.mean.copy(), stats.var.copy(), stats.count
    raw = json.loads((out / NORMALIZATION_FILE).read_text(encoding="utf-8"))["ret_rms"]
    venv.ret_rms.mean = np.asarray(raw["mean"], dtype=float)
    venv.ret_rms.var = np.asarray(raw["var"], dtype=float)
    venv.ret_rms.count = float(raw["count"])


# ------------------------------------------------------------------------------------------------- evaluation
def evaluate(model, obs_rms_venv, cfg: WorldRun, episodes: int, first_seed: int = EVAL_FIRST_SEED,
             batched_world: bool = True) -> dict:
    """Success rate and final robustness of the deterministic policy on the batched world (unless
    ``batched_world`` is False) and on the pymunk Gymnasium env: ``episodes`` seeded episodes each (seeds
    first_seed, first_seed + 1, ...), the training's noise. ``obs_rms_venv`` is the training's VecNormalize (its
    observation statistics, frozen)."""
    from impact_env.transport.batched import BatchedTransportWorld
    from impact_env.transport.gym_env import TransportEnv

    def act(obs: np.ndarray) -> np.ndarray:
        return model.predict(obs_rms_venv.normalize_obs(obs.astype(np.float32)), deterministic=True)[0]

    out: dict[str, Any] = {"episodes": episodes, "first_seed": first_seed}
    if batched_world:
        world = BatchedTransportWorld(cfg.scenario, episodes, **cfg.world_options())
        obs = world.reset(seeds=first_seed).cpu().numpy()
        for _ in range(world.horizon_steps):
            step_obs, _, _, _, info = world.step(torch.as_tensor(act(obs)))
            obs = step_obs.cpu().numpy()
        batched = info["robustness"].double().numpy()
        out["batched"] = {"success_rate": float((batched > 0).mean()), "robustness_mean": float(batched.mean()),
                          "robustness": [round(float(r), 6) for r in batched]}
    envs = [TransportEnv(cfg.scenario, **cfg.world_options()) for _ in range(episodes)]
    obs = np.stack([env.reset(seed=first_seed + i)[0] for i, env in enumerate(envs)])
    for _ in range(envs[0].core.horizon_steps):
        steps = [env.step(a) for env, a in zip(envs, act(obs))]
        obs = np.stack([s[0] for s in steps])
    infos = [s[4] for s in steps]
    pymunk = np.array([inf["robustness"] for inf in infos])
    fuel = np.array([inf.get("fuel_Ns", np.nan) for inf in infos])
    out["pymunk"] = {"success_rate": float((pymunk > 0).mean()), "robustness_mean": float(pymunk.mean()),
                     "fuel_Ns_mean": float(np.nanmean(fuel)) if np.isfinite(fuel).any() else None,
                     "robustness": [round(float(r), 6) for r in pymunk]}
    return out


# -------------------------------------------------------------------------------------------------------- run
def fix_run_settings(out: Path, settings: dict, free: Sequence[str], error: type[Exception] = ImpactEnvError) -> None:
    """Refuse a run folder whose ``config.json`` holds other ``settings`` than these (but the ``free`` ones, which
    change nothing of the training, such as the budget), then write them there. ``settings``: JSON values."""
    config_path = out / "config.json"
    if config_path.exists():
        before = json.loads(config_path.read_text(encoding="utf-8"))
        changed = sorted(k for k in settings if k not in free and before.get(k) != settings[k])
        if changed:
            raise error(f"{out} holds a run with other settings ({', '.join(changed)}: "
                        f"{', '.join(f'{before.get(k)!r} -> {settings[k]!r}' for k in changed)}); "
                        "use another --out or delete the folder")
    write_atomic(config_path, json.dumps(settings, indent=1))


def ppo_model(cfg: Any, venv: Any):
    """SB3's PPO with a run's settings (:class:`Sb3PpoConfig`'s PPO fields) on ``venv``."""
    from stable_baselines3 import PPO

    return PPO("MlpPolicy", venv, n_steps=cfg.n_steps, batch_size=cfg.batch_size, n_epochs=cfg.n_epochs,
               learning_rate=cfg.lr, gamma=cfg.gamma, gae_lambda=cfg.gae_lambda, clip_range=cfg.clip_range,
               ent_coef=cfg.ent_coef, seed=cfg.seed, device="cpu", verbose=0,
               policy_kwargs={"net_arch": list(cfg.hidden), "log_std_init": cfg.log_std_init})


def resume_run(model, venv, out: Path, logs: Sequence[Path], progress: bool) -> float:
    """The checkpoint of ``out`` (``state.json`` names its step count) into ``model`` and ``venv``, each of the
    ``logs`` cut to that step count; without a checkpoint, the logs are removed. Returns the run's training
    wall clock so far (s)."""
    state_path = out / "state.json"
    if not state_path.exists():
        for log in logs:
            log.unlink(missing_ok=True)
        return 0.0
    state = json.loads(state_path.read_text(encoding="utf-8"))
    restore(model, venv, out)
    model.num_timesteps = int(state["frames"])
    for log in logs:
        truncate_curve(log, state["frames"])
    if progress:
        print(f"resuming {out} at {state['frames']:,} env-steps", flush=True)
    return float(state["wall_s"])


def learn_in_chunks(model, cfg: Any, callback, save: Callable[[float], None], out: Path, progress: bool,
                    note: Callable[[], str] = lambda: "") -> None:
    """Train ``model`` up to ``cfg.frames`` in chunks of ``cfg.chunk_frames``, calling ``save(wall_s)`` after
    each (the checkpoint) and printing a line (``note()`` appended) when ``progress``."""
    while model.num_timesteps < cfg.frames:
        model.learn(min(cfg.chunk_frames, cfg.frames - model.num_timesteps), callback=callback,
                    reset_num_timesteps=False, progress_bar=False)
        save(callback.wall_s())
        if progress:
            wall = callback.wall_s()
            print(f"{out.name}: {model.num_timesteps:,} / {cfg.frames:,} env-steps, {wall:.0f} s "
                  f"({model.num_timesteps / max(wall, 1e-9):,.0f} env-steps/s){note()}", flush=True)


def run(cfg: Sb3PpoConfig, out: Path, progress: bool = True) -> dict:
    """Train (or resume) one run in ``out``; returns its result (also ``out``/result.json)."""
    from stable_baselines3.common.vec_env import VecNormalize

    result_path = out / "result.json"
    if result_path.exists():
        return json.loads(result_path.read_text(encoding="utf-8"))
    torch.set_num_threads(cfg.threads)
    out.mkdir(parents=True, exist_ok=True)
    fix_run_settings(out, json.loads(json.dumps(asdict(cfg))), ("frames", "checkpoint_frames", "eval_episodes",
                                                                "threads"), error=ValueError)
    curve = out / "curve.jsonl"
    state_path = out / "state.json"
    start = time.perf_counter()
    venv = VecNormalize(make_venv(cfg), gamma=cfg.gamma)
    model = ppo_model(cfg, venv)
    wall_before = resume_run(model, venv, out, [curve], progress)
    setup_s = time.perf_counter() - start
    callback = curve_callback(curve, wall_before)
    learn_in_chunks(model, cfg, callback, lambda wall: save_checkpoint(model, venv, cfg, out, wall), out, progress)
    train_wall = callback.wall_s() if model.num_timesteps > 0 else wall_before
    if state_path.exists():
        train_wall = json.loads(state_path.read_text(encoding="utf-8"))["wall_s"]
    start = time.perf_counter()
    venv.training = False
    evaluation = evaluate(model, venv, cfg, cfg.eval_episodes)
    rows = [json.loads(line) for line in curve.read_text(encoding="utf-8").splitlines() if line.strip()] \
        if curve.exists() else []
    result = {"kind": "sb3", "algorithm": "sb3_ppo", "task": cfg.scenario, "seed": cfg.seed,
              "env_steps": int(model.num_timesteps), "budget_env_steps": cfg.frames,
              "wall_s": round(float(train_wall), 1), "setup_s_last_start": round(setup_s, 1),
              "eval_s": round(time.perf_counter() - start, 1),
              "env_steps_per_s": round(model.num_timesteps / max(float(train_wall), 1e-9), 1),
              "evaluation": evaluation, "config": asdict(cfg), "curve_points": len(rows), "versions": _versions(),
              "threads": cfg.threads, "cpus": os.cpu_count(), "machine": platform.machine(),
              "load_average_1min_at_end": round(os.getloadavg()[0], 2)}
    write_atomic(result_path, json.dumps(result, indent=1))
    return result


def _versions() -> dict[str, str]:
    import importlib.metadata as md

    out = {}
    for name in ("torch", "stable_baselines3", "gymnasium", "impact_env"):
        try:
            out[name] = md.version(name)
        except md.PackageNotFoundError:
            pass
    return out


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scenario", help="a shipped scenario name or a scenario TOML path")
    parser.add_argument("--out", required=True, type=Path, help="the run folder (resumed if it holds a checkpoint)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--frames", type=int, default=Sb3PpoConfig.frames)
    parser.add_argument("--num-envs", type=int, default=Sb3PpoConfig.num_envs)
    parser.add_argument("--n-steps", type=int, default=Sb3PpoConfig.n_steps)
    parser.add_argument("--batch-size", type=int, default=Sb3PpoConfig.batch_size)
    parser.add_argument("--n-epochs", type=int, default=Sb3PpoConfig.n_epochs)
    parser.add_argument("--checkpoint-frames", type=int, default=Sb3PpoConfig.checkpoint_frames)
    parser.add_argument("--eval-episodes", type=int, default=Sb3PpoConfig.eval_episodes)
    parser.add_argument("--threads", type=int, default=Sb3PpoConfig.threads)
    parser.add_argument("--compile", action="store_true", help="the world's torch.compile kernels")
    args = parser.parse_args(argv)
    try:
        cfg = Sb3PpoConfig(args.scenario, seed=args.seed, frames=args.frames, num_envs=args.num_envs,
                           n_steps=args.n_steps, batch_size=args.batch_size, n_epochs=args.n_epochs,
                           checkpoint_frames=args.checkpoint_frames, eval_episodes=args.eval_episodes,
                           threads=args.threads, compile=args.compile)
    except ImpactEnvError as exc:
        parser.error(str(exc))
    result = run(cfg, args.out)
    print(json.dumps({k: result[k] for k in ("algorithm", "task", "seed", "env_steps", "wall_s")}
                     | {"pymunk": {k: v for k, v in result["evaluation"]["pymunk"].items() if k != "robustness"}}))


if __name__ == "__main__":
    main()
