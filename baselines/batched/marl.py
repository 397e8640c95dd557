"""Multi-agent PPO with BenchMARL (MAPPO, IPPO) on the batched impact world, or on VMAS's ``transport``.

    python -m baselines.batched.marl mappo corridor --seed 0 --frames 10000000 --out runs/mappo_corridor_s0
    python -m baselines.batched.marl ippo vmas/transport --seed 0 --out runs/ippo_vmas_s0   # in a VMAS venv

One run is one folder: BenchMARL's experiment (its checkpoints every ``--checkpoint-frames``), ``curve.jsonl``
(one line per collected batch: frames, wall clock, the finished training episodes' mean return, success rate
and final robustness) and, when the budget is spent, ``result.json`` (the configuration, the budget, the
wall clock and the final deterministic evaluation). A killed run started again with the same arguments
resumes from its last checkpoint (the curve lines after it are dropped, the episodes in flight restart); a
finished one is not run again. The hyperparameters are :class:`MarlConfig`'s, the same for every task and both
algorithms (MAPPO: a central critic on the state; IPPO: a critic on each agent's observation; both share
parameters between agents, BenchMARL's default).

The final evaluation of an impact task flies the policy deterministically and with sampled actions, on the
batched world and on the pymunk Gymnasium env, the same seeded episodes with the training's noise (why both:
``docs/rl_at_scale.md#evaluation-and-analysis``); a finished run without the sampled half is evaluated again
from its last checkpoint when it is run again. This module imports nothing of BenchMARL at import time (an
optional extra: :class:`MarlConfig` is importable and checked without it), and of ``impact_env`` only its config
checks and errors, read from their files where ``impact_env`` cannot be imported, so it runs in a venv with VMAS
(and no impact_env dependencies) for the external reference row.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import torch


def _standalone(name: str):
    """``impact_env/<name>.py`` as a module of its own (it needs only the standard library)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(f"_impact_env_{name}",
                                                  Path(__file__).resolve().parents[2] / "impact_env" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
    spec.loader.exec_module(module)  # type: ignore[union-attr]
    return module


try:
    from impact_env.config_checks import (
        check_choice,
        check_instance,
        check_integer,
        check_number,
        check_text,
        check_widths,
        fail,
    )
    from impact_env.errors import ImpactEnvError
except ImportError:  # a venv with VMAS and BenchMARL but not impact_env's dependencies (gymnasium, pymunk)
    _checks = _standalone("config_checks")
    check_choice, check_instance, check_integer, check_number, check_text, check_widths, fail = (
        _checks.check_choice, _checks.check_instance, _checks.check_integer, _checks.check_number,
        _checks.check_text, _checks.check_widths, _checks.fail)
    ImpactEnvError = _standalone("errors").ImpactEnvError  # type: ignore[misc]

ALGORITHMS = ("mappo", "ippo")
VMAS_TASK = "vmas/transport"


@dataclass(frozen=True)
class MarlConfig:
    """One MAPPO or IPPO run (BenchMARL's names in brackets)."""

    algorithm: str
    """``mappo`` or ``ippo``."""
    task: str
    """A shipped scenario name, a scenario TOML path, or ``vmas/transport``."""
    seed: int = 0
    """Seeds the networks, BenchMARL and the envs."""
    frames: int = 10_000_000
    """Env-step budget (``max_n_frames``): one frame is one step of one env, all its agents included."""
    num_envs: int = 512
    """Envs collected in parallel (``on_policy_n_envs_per_worker``)."""
    frames_per_batch: int = 51_200
    """Frames per PPO iteration (``on_policy_collected_frames_per_batch``): 100 steps of each env."""
    epochs: int = 4
    """Passes over each batch (``on_policy_n_minibatch_iters``)."""
    minibatch_size: int = 10_240
    """Frames per gradient step (``on_policy_minibatch_size``)."""
    lr: float = 3e-4
    """Adam learning rate."""
    gamma: float = 0.99
    """Discount."""
    lmbda: float = 0.95
    """GAE lambda."""
    entropy_coef: float = 0.0
    """Entropy bonus."""
    hidden: tuple[int, ...] = (64, 64)
    """Hidden layer widths of the actor and of the critic (tanh MLPs)."""
    thrust_noise: float = 0.05
    """Impact tasks: multiplicative thrust noise (the expert-vs-learned benchmark's condition)."""
    initial_position_noise_m: float = 0.05
    """Impact tasks: objects start within this radius (m)."""
    checkpoint_frames: int = 1_024_000
    """Frames between checkpoints (a multiple of ``frames_per_batch``)."""
    eval_episodes: int = 100
    """Episodes of the final deterministic evaluation, per world."""
    threads: int = 1
    """torch threads of the run."""
    extra: dict[str, Any] = field(default_factory=dict)
    """Further task options (the batched world's, e.g. ``reward_mode``)."""

    def __post_init__(self) -> None:
        check_choice(self, "algorithm", ImpactEnvError, ALGORITHMS)
        check_text(self, "task", ImpactEnvError)
        check_integer(self, "seed", ImpactEnvError, low=0)
        for name in ("frames", "num_envs", "frames_per_batch", "epochs", "minibatch_size", "checkpoint_frames",
                     "eval_episodes", "threads"):
            check_integer(self, name, ImpactEnvError, low=1)
        check_number(self, "lr", ImpactEnvError, low=0, low_open=True)
        check_number(self, "gamma", ImpactEnvError, low=0, high=1, low_open=True)
        check_number(self, "lmbda", ImpactEnvError, low=0, high=1)
        for name in ("entropy_coef", "thrust_noise", "initial_position_noise_m"):
            check_number(self, name, ImpactEnvError, low=0)
        check_widths(self, "hidden", ImpactEnvError)
        check_instance(self, "extra", ImpactEnvError, dict, what="a dict of task options")
        if self.frames_per_batch % self.num_envs:
            fail("MarlConfig.frames_per_batch", self.frames_per_batch, f"a multiple of num_envs ({self.num_envs})",
                 ImpactEnvError)
        if self.checkpoint_frames % self.frames_per_batch:
            fail("MarlConfig.checkpoint_frames", self.checkpoint_frames,
                 f"a multiple of frames_per_batch ({self.frames_per_batch})", ImpactEnvError)

    @property
    def is_vmas(self) -> bool:
        return self.task == VMAS_TASK


# ------------------------------------------------------------------------------------------ BenchMARL parts
def _task(cfg: MarlConfig):
    if cfg.is_vmas:
        from benchmarl.environments import VmasTask

        return VmasTask.TRANSPORT.get_from_yaml()
    from baselines.batched.benchmarl_task import ImpactTaskClass

    return ImpactTaskClass(cfg.task, {"thrust_noise": cfg.thrust_noise,
                                      "initial_position_noise_m": cfg.initial_position_noise_m,
                                      "compile_min_envs": cfg.num_envs, **cfg.extra})


def _experiment_config(cfg: MarlConfig, folder: Path, restore: Path | None):
    from benchmarl.experiment import ExperimentConfig

    ec = ExperimentConfig.get_from_yaml()
    ec.max_n_frames = cfg.frames
    ec.max_n_iters = None
    ec.on_policy_collected_frames_per_batch = cfg.frames_per_batch
    ec.on_policy_n_envs_per_worker = cfg.num_envs
    ec.on_policy_n_minibatch_iters = cfg.epochs
    ec.on_policy_minibatch_size = cfg.minibatch_size
    ec.lr = cfg.lr
    ec.gamma = cfg.gamma
    ec.evaluation = False  # the deterministic evaluation runs once, at the end (evaluate())
    ec.render = False
    ec.loggers = ["csv"]
    ec.create_json = False
    ec.save_folder = str(folder)
    ec.restore_file = None if restore is None else str(restore)
    ec.checkpoint_interval = cfg.checkpoint_frames
    ec.checkpoint_at_end = True
    ec.keep_checkpoints_num = 1
    ec.exclude_buffer_from_checkpoint = True  # an on-policy buffer is refilled at once
    return ec


def _algorithm_config(cfg: MarlConfig):
    from benchmarl.algorithms import IppoConfig, MappoConfig

    ac = (MappoConfig if cfg.algorithm == "mappo" else IppoConfig).get_from_yaml()
    ac.lmbda = cfg.lmbda
    ac.entropy_coef = cfg.entropy_coef
    return ac


def _model_config(cfg: MarlConfig):
    from benchmarl.models import MlpConfig

    mc = MlpConfig.get_from_yaml()
    mc.num_cells = list(cfg.hidden)
    return mc


def _episodes(batch) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]:
    """(returns, successes, final robustness or None) of the episodes that ended in a collected batch."""
    done = batch.get(("next", "done")).squeeze(-1)
    group = next(k for k in batch.get("next").keys() if k not in ("done", "terminated", "truncated", "state")
                 and hasattr(batch.get(("next", k)), "keys"))
    returns = batch.get(("next", group, "episode_reward"))[done][:, 0, 0]  # [episodes, agents, 1]: agent 0's
    info = batch.get(("next", group), None)
    if info is not None and ("info", "is_success") in info.keys(True):
        success = info.get(("info", "is_success"))[done][:, 0, 0].float()
        robustness = info.get(("info", "robustness"))[done][:, 0, 0].float()
        return returns, success, robustness
    return returns, torch.full_like(returns, float("nan")), None  # VMAS: no success flag in the batch


def _curve_logger_class() -> type:
    """:class:`CurveLogger`, a BenchMARL callback made on first use (so that this module imports without
    BenchMARL) and kept as this module's ``CurveLogger``, where pickle (BenchMARL pickles its callbacks) finds
    it."""
    if "CurveLogger" in globals():
        return globals()["CurveLogger"]
    from benchmarl.experiment.callback import Callback

    class CurveLogger(Callback):
        """One line of ``curve`` per collected batch; the wall clock is carried through checkpoints."""

        def __init__(self, curve: Path) -> None:
            super().__init__()
            self.curve = curve
            self.wall_before = 0.0
            self.t0 = time.perf_counter()

        def wall_s(self) -> float:
            """Wall clock of the run so far (s), over every start of it."""
            return self.wall_before + time.perf_counter() - self.t0

        def on_setup(self) -> None:
            self.t0 = time.perf_counter()

        def on_batch_collected(self, batch) -> None:
            returns, success, robustness = _episodes(batch)
            exp = self.experiment
            n = returns.numel()
            row = {"frames": exp.total_frames, "wall_s": round(self.wall_s(), 2),
                   "iteration": exp.n_iters_performed, "episodes": int(n),
                   "return_mean": float(returns.mean()) if n else None,
                   "success_rate": float(success.mean()) if n and not bool(success.isnan().any()) else None,
                   "robustness_mean": float(robustness.mean()) if robustness is not None and n else None}
            with self.curve.open("a", encoding="utf-8") as f:
                f.write(json.dumps(row) + "\n")

        def on_state_dict(self, state_dict) -> None:
            state_dict["impact_env_wall_s"] = self.wall_s()

        def on_load_state_dict(self, state_dict) -> None:
            self.wall_before = float(state_dict.get("impact_env_wall_s", 0.0))
            self.t0 = time.perf_counter()

    CurveLogger.__qualname__ = "CurveLogger"
    globals()["CurveLogger"] = CurveLogger
    return CurveLogger


def __getattr__(name: str) -> Any:
    if name == "CurveLogger":
        return _curve_logger_class()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _latest_checkpoint(folder: Path) -> Path | None:
    found = sorted(folder.glob("*/checkpoints/checkpoint_*.pt"), key=lambda p: int(p.stem.split("_")[-1]))
    return found[-1] if found else None


def _truncate_curve(curve: Path, frames: int) -> None:
    if not curve.exists():
        return
    rows = [line for line in curve.read_text(encoding="utf-8").splitlines()
            if line.strip() and json.loads(line)["frames"] <= frames]
    tmp = curve.with_suffix(".tmp")
    tmp.write_text("".join(r + "\n" for r in rows), encoding="utf-8")
    os.replace(tmp, curve)


# ------------------------------------------------------------------------------------------------- evaluation
def _policy_actions(policy, group: str, observations: torch.Tensor, sampled: bool = False) -> torch.Tensor:
    from tensordict import TensorDict
    from torchrl.envs.utils import ExplorationType, set_exploration_type

    n, r = observations.shape[:2]
    td = TensorDict({group: TensorDict({"observation": observations}, batch_size=(n, r))}, batch_size=(n,))
    mode = ExplorationType.RANDOM if sampled else ExplorationType.DETERMINISTIC
    with torch.no_grad(), set_exploration_type(mode):
        return policy(td).get((group, "action"))


def _scores(robustness) -> dict:
    return {"success_rate": float((robustness > 0).mean()), "robustness_mean": float(robustness.mean())}


def evaluate_impact(policy, cfg: MarlConfig, episodes: int, first_seed: int = 1_000_000) -> dict:
    """Success rate and final robustness of the policy on the batched world and on the pymunk Gymnasium env:
    ``episodes`` seeded episodes each, with the training's noise. The top-level ``batched`` and ``pymunk`` are
    the deterministic policy's; ``sampled`` holds the same two for actions drawn from the policy (torch seeded
    with ``first_seed`` before each world's episodes, so both worlds get the same draws)."""
    out: dict[str, Any] = {"episodes": episodes, "first_seed": first_seed}
    for sampled in (False, True):
        scores = {world: _scores(r) for world, r in _fly(policy, cfg, episodes, first_seed, sampled).items()}
        if sampled:
            out["sampled"] = scores
        else:
            out.update(scores)
    return out


def _fly(policy, cfg: MarlConfig, episodes: int, first_seed: int, sampled: bool) -> dict:
    """Final robustness per episode on each world (``batched``, ``pymunk``)."""
    import numpy as np

    from impact_env.transport.batched import BatchedTransportWorld
    from impact_env.transport.gym_env import TransportEnv

    noise = {"thrust_noise": cfg.thrust_noise, "initial_position_noise_m": cfg.initial_position_noise_m,
             **{k: v for k, v in cfg.extra.items() if k != "dtype"}}
    world = BatchedTransportWorld(cfg.task, episodes, **noise)
    world.reset(seeds=first_seed)
    torch.manual_seed(first_seed)
    for _ in range(world.horizon_steps):
        _, _, terminated, _, info = world.step(_policy_actions(policy, "agents", world.agent_observations(), sampled))
    batched = info["robustness"].double().numpy()
    envs = [TransportEnv(cfg.task, **noise) for _ in range(episodes)]
    cores = [env.core for env in envs]
    for i, env in enumerate(envs):
        env.reset(seed=first_seed + i)
    R = cores[0].n_robots
    torch.manual_seed(first_seed)
    for _ in range(world.horizon_steps):
        obs = torch.tensor(np.stack([np.stack([c.agent_observation(r) for r in range(R)]) for c in cores]))
        actions = _policy_actions(policy, "agents", obs, sampled).reshape(episodes, -1).double().numpy()
        infos = [env.step(a)[4] for env, a in zip(envs, actions)]
    return {"batched": batched, "pymunk": np.array([inf["robustness"] for inf in infos])}


def evaluate_vmas(experiment, episodes: int) -> dict:
    """Mean return and success rate (package on the goal before max_steps) of the deterministic policy."""
    from torchrl.envs.utils import ExplorationType, set_exploration_type

    env = experiment.task.get_env_fun(episodes, True, 1_000_000, "cpu")()
    with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
        td = env.rollout(experiment.max_steps, policy=experiment.policy, break_when_any_done=False)
    # one episode per env (the rollout lasts max_steps): VMAS reports done at max_steps as well, so an episode
    # succeeded when it ended earlier (the package reached the goal)
    done = td.get(("next", "done")).squeeze(-1)  # [envs, steps]
    first = torch.where(done.any(1), done.float().argmax(1),
                        torch.full_like(done[:, 0], done.shape[1], dtype=torch.long))
    reward = (td.get(("next", "agents", "reward"))[:, :, 0, 0] * (torch.arange(done.shape[1]) <= first[:, None])).sum(1)
    success = (first < experiment.max_steps - 1).float()
    return {"episodes": episodes, "return_mean": float(reward.mean()), "success_rate": float(success.mean())}


# -------------------------------------------------------------------------------------------------------- run
def run(cfg: MarlConfig, out: Path) -> dict:
    """Train (or resume) one run in ``out``; returns its result (also ``out``/result.json)."""
    result_path = out / "result.json"
    earlier = json.loads(result_path.read_text(encoding="utf-8")) if result_path.exists() else None
    if earlier is not None and (cfg.is_vmas or "sampled" in earlier["evaluation"]):
        return earlier
    from benchmarl.experiment import Experiment

    torch.set_num_threads(cfg.threads)
    out.mkdir(parents=True, exist_ok=True)
    (out / "config.json").write_text(json.dumps(asdict(cfg), indent=1), encoding="utf-8")
    curve = out / "curve.jsonl"
    restore = _latest_checkpoint(out)
    logger = _curve_logger_class()(curve)
    if restore is None:
        curve.unlink(missing_ok=True)
    else:
        _truncate_curve(curve, int(restore.stem.split("_")[-1]))
        print(f"resuming {out} from {restore.name}", flush=True)
    start = time.perf_counter()
    experiment = Experiment(task=_task(cfg), algorithm_config=_algorithm_config(cfg), model_config=_model_config(cfg),
                            critic_model_config=_model_config(cfg), seed=cfg.seed,
                            config=_experiment_config(cfg, out, restore), callbacks=[logger])
    setup_s = time.perf_counter() - start
    if earlier is not None:  # finished before the sampled evaluation existed: evaluate its last checkpoint again
        start = time.perf_counter()
        earlier["evaluation"] = evaluate_impact(experiment.policy, cfg, cfg.eval_episodes)
        earlier["eval_s"] = round(time.perf_counter() - start, 1)
        _write_json(result_path, earlier)
        return earlier
    if experiment.total_frames < cfg.frames:
        experiment.run()
    train_wall = logger.wall_s()
    start = time.perf_counter()
    policy = experiment.policy
    evaluation = (evaluate_vmas(experiment, cfg.eval_episodes) if cfg.is_vmas
                  else evaluate_impact(policy, cfg, cfg.eval_episodes))
    rows = [json.loads(line) for line in curve.read_text(encoding="utf-8").splitlines() if line.strip()]
    result = {"kind": "marl", "algorithm": cfg.algorithm, "task": cfg.task, "seed": cfg.seed,
              "env_steps": int(experiment.total_frames), "budget_env_steps": cfg.frames,
              "wall_s": round(train_wall, 1), "benchmarl_iteration_s": round(float(experiment.total_time), 1),
              "setup_s_last_start": round(setup_s, 1), "eval_s": round(time.perf_counter() - start, 1),
              "env_steps_per_s": round(experiment.total_frames / max(train_wall, 1e-9), 1),
              "evaluation": evaluation, "config": asdict(cfg), "curve_points": len(rows),
              "versions": _versions(), "threads": cfg.threads, "cpus": os.cpu_count(), "machine": platform.machine(),
              "load_average_1min_at_end": round(os.getloadavg()[0], 2)}
    _write_json(result_path, result)
    return result


def _write_json(path: Path, data: dict) -> None:
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(data, indent=1), encoding="utf-8")
    os.replace(tmp, path)


def _versions() -> dict[str, str]:
    import importlib.metadata as md

    out = {}
    for name in ("torch", "torchrl", "tensordict", "benchmarl", "vmas", "impact_env"):
        try:
            out[name] = md.version(name)
        except md.PackageNotFoundError:
            pass
    return out


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("algorithm", choices=ALGORITHMS)
    parser.add_argument("task", help="a shipped scenario, a scenario TOML path, or vmas/transport")
    parser.add_argument("--out", required=True, type=Path, help="the run folder (resumed if it holds a checkpoint)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--frames", type=int, default=MarlConfig.frames)
    parser.add_argument("--num-envs", type=int, default=MarlConfig.num_envs)
    parser.add_argument("--frames-per-batch", type=int, default=MarlConfig.frames_per_batch)
    parser.add_argument("--minibatch-size", type=int, default=MarlConfig.minibatch_size)
    parser.add_argument("--epochs", type=int, default=MarlConfig.epochs)
    parser.add_argument("--checkpoint-frames", type=int, default=MarlConfig.checkpoint_frames)
    parser.add_argument("--eval-episodes", type=int, default=MarlConfig.eval_episodes)
    parser.add_argument("--threads", type=int, default=MarlConfig.threads)
    args = parser.parse_args(argv)
    try:
        cfg = MarlConfig(args.algorithm, args.task, seed=args.seed, frames=args.frames, num_envs=args.num_envs,
                         frames_per_batch=args.frames_per_batch, minibatch_size=args.minibatch_size,
                         epochs=args.epochs, checkpoint_frames=args.checkpoint_frames,
                         eval_episodes=args.eval_episodes, threads=args.threads)
    except ImpactEnvError as exc:
        parser.error(str(exc))
    result = run(cfg, args.out)
    print(json.dumps({k: result[k] for k in ("algorithm", "task", "seed", "env_steps", "wall_s", "evaluation")}))


if __name__ == "__main__":
    main()
