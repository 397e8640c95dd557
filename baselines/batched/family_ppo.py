"""One goal-conditioned PPO policy for a task family, trained on many generated tasks at once on the batched world.

    python -m baselines.batched.family_ppo throw_and_catch --tasks 1000:1032 --seed 0 --frames 5000000 \\
        --out runs/family_ppo/throw_and_catch_s0

stable-baselines3's PPO (the settings of :mod:`baselines.batched.sb3_ppo`, a wider network) on a
:class:`~impact_env.transport.batched.family_world.TaskFamilyWorld`: ``envs_per_task`` envs of each training
task side by side, every observation in the family's padded layout (bodies, time left, the task's regions and
windows, its obstacles), so the one policy must read its task from the observation. The training tasks are
generated seeds (by default 1000 and up, so the planner-filtered tasks of ``benchmarks.task_generator``, seeds
0 and up, stay held out); they are not filtered by the planner, so a few may be impossible, which costs
samples but teaches nothing false. The run folder is :mod:`baselines.batched.sb3_ppo`'s (checkpoints in the
package's pickle-free form, ``state.json``, ``curve.jsonl``; a killed run resumes from its last checkpoint,
and a finished one given a larger ``--frames`` trains on, keeping its earlier ``result_<budget>.json``), and
:class:`FamilyPpoPolicy` flies its deterministic policy on any task of the family (the family env ids, or
:class:`~impact_env.transport.task_observation.TaskConditioned`). ``benchmarks/family_rl.py`` evaluates it on
held-out tasks against the expert.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from baselines.batched.sb3_ppo import check_ppo_settings
from impact_env.config_checks import check_choice, check_integer, fail
from impact_env.errors import ImpactEnvError, ModelFileError
from impact_env.results_store import atomic_path, write_atomic
from impact_env.transport.generate import FAMILIES

__all__ = ["FamilyPpoConfig", "FamilyPpoPolicy", "run"]

TRAINER = "baselines.batched.family_ppo (batched world, many tasks)"


@dataclass(frozen=True)
class FamilyPpoConfig:
    """One goal-conditioned PPO run on a family's generated tasks."""

    family: str
    """The task family (its padded layout is the observation)."""
    tasks: tuple[int, ...] = tuple(range(1000, 1032))
    """Generated-task seeds trained on (not planner-filtered)."""
    envs_per_task: int = 16
    """Envs of each task's world (the batch is ``len(tasks) * envs_per_task`` envs)."""
    seed: int = 0
    """Seeds the networks and the envs (env i of the batch starts at seed * 100,000 + i)."""
    frames: int = 5_000_000
    """Env-step budget."""
    n_steps: int = 16
    """Steps of each env per rollout."""
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
    hidden: tuple[int, ...] = (128, 128)
    """Hidden layer widths of the policy and value networks (wider than one scenario's: it reads the task)."""
    log_std_init: float = -0.5
    """Initial log standard deviation of the Gaussian policy."""
    thrust_noise: float = 0.05
    """Multiplicative thrust noise."""
    initial_position_noise_m: float = 0.05
    """Objects start within this radius (m)."""
    reward_mode: str = "dense"
    """The world's reward."""
    checkpoint_frames: int = 262_144
    """Env-steps between checkpoints (rounded up to whole rollouts)."""
    threads: int = 1
    """torch threads."""

    def __post_init__(self) -> None:
        check_choice(self, "family", ImpactEnvError, FAMILIES)
        if not isinstance(self.tasks, tuple) or not self.tasks or any(
                isinstance(t, bool) or not isinstance(t, (int, np.integer)) or t < 0 for t in self.tasks):
            fail("FamilyPpoConfig.tasks", self.tasks, "a non-empty tuple of generated-task seeds (ints >= 0)",
                 ImpactEnvError)
        if len(set(self.tasks)) != len(self.tasks):
            fail("FamilyPpoConfig.tasks", self.tasks, "seeds without repeats", ImpactEnvError)
        check_integer(self, "envs_per_task", ImpactEnvError, low=1)
        check_ppo_settings(self, self.num_envs)

    @property
    def num_envs(self) -> int:
        return len(self.tasks) * self.envs_per_task

    @property
    def chunk_frames(self) -> int:
        rollout = self.num_envs * self.n_steps
        return -(-self.checkpoint_frames // rollout) * rollout

    def world_options(self) -> dict[str, Any]:
        return {"thrust_noise": self.thrust_noise, "initial_position_noise_m": self.initial_position_noise_m,
                "reward_mode": self.reward_mode}


def _save(model, venv, cfg: FamilyPpoConfig, out: Path, wall_s: float) -> None:
    """model.zip, vecnormalize.json, train.json, then state.json (which names the step count of the others)."""
    from baselines.model_files import save_normalization

    with atomic_path(out / "model.zip") as tmp:
        model.save(tmp)
    with atomic_path(out / "vecnormalize.json") as tmp:
        save_normalization(venv, tmp)
    write_atomic(out / "train.json", json.dumps({
        "algo": "ppo", "family": cfg.family, "tasks": list(cfg.tasks), "timesteps": cfg.frames,
        "timesteps_trained": int(model.num_timesteps), "n_envs": cfg.num_envs, "seed": cfg.seed,
        "env_options": cfg.world_options(), "hidden": list(cfg.hidden), "wall_time_s": round(wall_s, 2),
        "trainer": TRAINER}, indent=2))
    write_atomic(out / "state.json", json.dumps({"frames": int(model.num_timesteps), "wall_s": round(wall_s, 2)}))


def run(cfg: FamilyPpoConfig, out: Path, progress: bool = True) -> dict:
    """Train (or resume) one run in ``out``; returns its summary (also ``out``/result.json)."""
    import torch
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    from baselines.batched.sb3_ppo import curve_callback, fix_run_settings, learn_in_chunks, ppo_model, resume_run
    from impact_env.transport.batched.family_world import TaskFamilyWorld
    from impact_env.transport.batched.sb3_vec_env import TransportSB3VecEnv

    result_path = out / "result.json"
    if result_path.exists():
        done = json.loads(result_path.read_text(encoding="utf-8"))
        if done["budget_env_steps"] >= cfg.frames:
            return done
        # a larger budget trains the finished run on from its last checkpoint; its result stays beside it
        result_path.rename(out / f"result_{done['budget_env_steps']}.json")
    torch.set_num_threads(cfg.threads)
    out.mkdir(parents=True, exist_ok=True)
    now = json.loads(json.dumps(asdict(cfg)))
    fix_run_settings(out, now, ("frames", "checkpoint_frames", "threads"))
    curve, state_path = out / "curve.jsonl", out / "state.json"
    world = TaskFamilyWorld(cfg.family, list(cfg.tasks), cfg.envs_per_task, **cfg.world_options())
    raw = TransportSB3VecEnv(world=world)
    raw.seed(cfg.seed * 100_000)
    venv = VecNormalize(VecMonitor(raw), gamma=cfg.gamma)
    model = ppo_model(cfg, venv)
    callback = curve_callback(curve, resume_run(model, venv, out, [curve], progress))
    learn_in_chunks(model, cfg, callback, lambda wall: _save(model, venv, cfg, out, wall), out, progress)
    wall = json.loads(state_path.read_text(encoding="utf-8"))["wall_s"]
    result = {"family": cfg.family, "seed": cfg.seed, "env_steps": int(model.num_timesteps),
              "budget_env_steps": cfg.frames, "train_tasks": len(cfg.tasks), "wall_s": wall,
              "env_steps_per_s": round(model.num_timesteps / max(wall, 1e-9), 1), "config": now,
              "finished": time.strftime("%Y-%m-%d %H:%M:%S")}
    write_atomic(result_path, json.dumps(result, indent=1))
    return result


class FamilyPpoPolicy:
    """A run's deterministic policy as a controller on the family's padded layout (``reset`` and ``act``), for
    :func:`impact_env.rollout.run_episode` on a family env id or a ``TaskConditioned`` env. The model and its
    normalisation load through :mod:`baselines.model_files`, which decodes no pickle."""

    name = "family_ppo"

    def __init__(self, run_dir: str | Path) -> None:
        from baselines import model_files
        from impact_env.transport.generate import FAMILY_LIMITS
        from impact_env.transport.task_observation import padded_spaces

        run_dir = Path(run_dir)
        config_path = run_dir / "config.json"
        if not (run_dir / "model.zip").is_file() or not config_path.is_file():
            raise ModelFileError(f"{run_dir} is not a family PPO run folder (model.zip and config.json are needed): "
                                 "train it with python -m baselines.batched.family_ppo")
        self.family = json.loads(config_path.read_text(encoding="utf-8"))["family"]
        if self.family not in FAMILY_LIMITS:
            raise ModelFileError(f"{config_path} names an unknown family {self.family!r}")
        observation_space, action_space = padded_spaces(FAMILY_LIMITS[self.family])
        self.model = model_files.load_model(run_dir / "model.zip", "ppo", observation_space, action_space)
        self.normalization = model_files.load_normalization(run_dir, observation_space.shape[0])

    def reset(self, env: Any = None, seed: int | None = None) -> None:
        pass

    def act(self, observation: np.ndarray, info: dict[str, Any] | None = None) -> np.ndarray:
        obs = np.asarray(observation, dtype=np.float32)
        if self.normalization is not None:
            obs = self.normalization.apply(obs)
        return self.model.predict(obs, deterministic=True)[0]


def parse_tasks(text: str) -> tuple[int, ...]:
    """``A:B`` (seeds A to B-1) or ``a,b,c``."""
    try:
        if ":" in text:
            a, b = (int(x) for x in text.split(":"))
            return tuple(range(a, b))
        return tuple(int(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"--tasks takes A:B or a,b,c (generated-task seeds), got {text!r}") from None


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("family", choices=FAMILIES)
    parser.add_argument("--out", required=True, type=Path, help="the run folder (resumed if it holds a checkpoint)")
    parser.add_argument("--tasks", type=parse_tasks, default=FamilyPpoConfig.tasks,
                        help="generated-task seeds trained on, A:B or a,b,c (default 1000:1032)")
    parser.add_argument("--envs-per-task", type=int, default=FamilyPpoConfig.envs_per_task)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--frames", type=int, default=FamilyPpoConfig.frames)
    parser.add_argument("--n-steps", type=int, default=FamilyPpoConfig.n_steps)
    parser.add_argument("--batch-size", type=int, default=FamilyPpoConfig.batch_size)
    parser.add_argument("--checkpoint-frames", type=int, default=FamilyPpoConfig.checkpoint_frames)
    parser.add_argument("--threads", type=int, default=FamilyPpoConfig.threads)
    args = parser.parse_args(argv)
    try:
        cfg = FamilyPpoConfig(args.family, tasks=args.tasks, envs_per_task=args.envs_per_task, seed=args.seed,
                              frames=args.frames, n_steps=args.n_steps, batch_size=args.batch_size,
                              checkpoint_frames=args.checkpoint_frames, threads=args.threads)
    except ImpactEnvError as exc:
        parser.error(str(exc))
    print(json.dumps(run(cfg, args.out)))


if __name__ == "__main__":
    main()
