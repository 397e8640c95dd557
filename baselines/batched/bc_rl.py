"""BC+RL: PPO fine-tuning of a behaviour-cloned policy with an auxiliary behaviour-cloning loss, on the batched
world: ``impact-env bc-rl SCENARIO --policy BC_FOLDER``.

The policy starts as the ``bc`` or ``dagger`` policy of ``--policy``, with its architecture and its observation
statistics, which stay frozen (the weights were fitted to them). Every PPO gradient step adds the expert pairs'
negative log-likelihood, weighted by ``bc_weight * 0.5 ** ((t - warm-up) / bc_half_life_frames)`` at env-step t
(:mod:`baselines.batched.bc_ppo`); during the first ``critic_warmup_rollouts`` only the fresh value network
learns. The expert pairs are the labels of the DAgger run folder (``rounds/``; BC is ``dagger --rounds 0``),
else the Minari dataset ``impact-env bc`` was fitted to. A rollout is by default one whole episode of every
env: the batched world's envs run in lockstep, and with 16-step rollouts every corridor run of 2 million
env-steps lost success, while whole-episode rollouts kept it (docs/baselines.md, results/bc_rl/).

Why stable-baselines3's PPO: the BC policy is an SB3 ``MlpPolicy``, so the start is a copy of its weights; SB3's
PPO already trains on the batched world (:mod:`baselines.batched.sb3_ppo`, whose checkpoints, resume, curve and
evaluation this module reuses), and its model folder is the one ``run`` and ``bench`` fly without unpickling.
The ``imitation`` library (1.0.1) would pin gymnasium 0.29 and SB3 2.2; TorchRL's MAPPO has another policy class.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from baselines.batched.bc_ppo import BCRegularisedPPO, FrozenStatistics
from baselines.batched.sb3_ppo import (
    curve_callback,
    evaluate,
    fix_run_settings,
    learn_in_chunks,
    make_venv,
    resume_run,
    save_checkpoint,
)
from impact_env.config_checks import check_choice, check_flag, check_integer, check_number, check_text, fail
from impact_env.errors import ImpactEnvError
from impact_env.results_store import write_atomic
from impact_env.transport.core import REWARD_MODES

TRAINER = "baselines.batched.bc_rl (BC+RL, batched world)"


@dataclass(frozen=True)
class BcRlConfig:
    """One BC+RL run: the BC policy, the BC term and its decay, PPO on the batched world (module docstring)."""

    scenario: str
    """A shipped scenario name or a scenario TOML path (the one the policy was cloned on)."""
    policy: str
    """The BC or DAgger run folder (``model.zip``, ``vecnormalize.json``, ``train.json``; ``rounds/`` for DAgger)."""
    dataset_dir: str | None = None
    """The Minari datasets folder of the expert pairs when ``policy`` has no ``rounds/``; None: Minari's own."""
    seed: int = 0
    """Seeds PPO (SB3's ``seed``), the BC minibatches and the envs (env i starts at seed * 100,000 + i)."""
    frames: int = 1_000_000
    """Env-step budget of the fine-tuning (the critic's warm-up included)."""
    bc_weight: float = 1.0
    """Weight of the BC loss (the expert actions' negative log-likelihood) against PPO's, before it decays."""
    bc_half_life_frames: int | None = 1_000_000
    """Env-steps after the warm-up in which the BC weight halves; None: constant."""
    bc_batch_size: int = 2048
    """Expert pairs per gradient step."""
    critic_warmup_rollouts: int = 1
    """Rollouts at the start during which only the value network learns (0: none)."""
    log_std: float | None = None
    """The Gaussian's log standard deviation at the start; None: the BC policy's own."""
    num_envs: int = 256
    """Envs of the batch."""
    n_steps: int | None = None
    """Steps of each env per rollout; None: the scenario's horizon (every rollout one whole episode per env)."""
    batch_size: int | None = None
    """Env-steps per gradient step, a divisor of num_envs x n_steps; None: num_envs x the largest divisor of
    n_steps up to 32."""
    n_epochs: int = 4
    """Passes over each rollout."""
    lr: float = 1e-4
    """Adam learning rate (constant; smaller than PPO's from scratch: the start is already a good policy)."""
    gamma: float = 0.999
    """Discount."""
    gae_lambda: float = 0.95
    """GAE lambda."""
    clip_range: float = 0.2
    """PPO's clip range."""
    ent_coef: float = 0.0
    """Entropy bonus."""
    normalize_advantage: bool = False
    """Normalise the advantages in each minibatch (SB3's default). Off: the dense reward is a robustness increment,
    zero wherever the task's minimum does not move (most of a corridor episode), and normalising a minibatch of
    near-zero advantages turns the critic's noise into full-size policy steps."""
    thrust_noise: float = 0.05
    """Multiplicative thrust noise of the training world."""
    initial_position_noise_m: float = 0.05
    """Objects start within this radius (m)."""
    reward_mode: str = "dense"
    """The world's reward (``dense``, ``sparse``, ``conjuncts``)."""
    fuel_penalty: float = 0.0
    """Reward cost per N s of fuel."""
    restitution: float | None = None
    """Simulate with this restitution instead of the scenario's; None: the scenario's."""
    impact_velocity_noise_mps: float = 0.0
    """A uniform error in [-M, M] m/s per axis on an object's velocity after each robot-object impact."""
    compile: bool = False
    """Run the world's torch.compile kernels."""
    checkpoint_frames: int = 131_072
    """Env-steps between checkpoints (rounded up to whole rollouts)."""
    eval_episodes: int = 50
    """Episodes of the deterministic evaluations on the pymunk env (the BC policy's before training, then the
    result's), the same seeds for both."""
    eval_batched_world: bool = False
    """Also evaluate on the batched world (as :mod:`baselines.batched.sb3_ppo` does)."""
    threads: int = 1
    """torch threads of the run."""

    def __post_init__(self) -> None:
        for name in ("scenario", "policy"):
            check_text(self, name, ImpactEnvError)
        check_text(self, "dataset_dir", ImpactEnvError, none="Minari's own folder")
        check_integer(self, "seed", ImpactEnvError, low=0)
        for name in ("frames", "bc_batch_size", "num_envs", "n_epochs", "checkpoint_frames", "eval_episodes",
                     "threads"):
            check_integer(self, name, ImpactEnvError, low=1)
        check_integer(self, "n_steps", ImpactEnvError, low=1, none="the scenario's horizon")
        check_integer(self, "batch_size", ImpactEnvError, low=1, none="num_envs x a divisor of n_steps up to 32")
        check_integer(self, "bc_half_life_frames", ImpactEnvError, low=1, none="a constant weight")
        check_integer(self, "critic_warmup_rollouts", ImpactEnvError, low=0)
        check_number(self, "bc_weight", ImpactEnvError, low=0)
        check_number(self, "log_std", ImpactEnvError, low=-20, high=2, none="the BC policy's own")
        for name in ("lr", "clip_range"):
            check_number(self, name, ImpactEnvError, low=0, low_open=True)
        check_number(self, "gamma", ImpactEnvError, low=0, high=1, low_open=True)
        check_number(self, "gae_lambda", ImpactEnvError, low=0, high=1)
        check_number(self, "ent_coef", ImpactEnvError, low=0)
        for name in ("thrust_noise", "initial_position_noise_m", "fuel_penalty", "impact_velocity_noise_mps"):
            check_number(self, name, ImpactEnvError, low=0)
        check_number(self, "restitution", ImpactEnvError, low=0, high=1, none="the scenario's")
        check_choice(self, "reward_mode", ImpactEnvError, REWARD_MODES)
        for name in ("compile", "eval_batched_world", "normalize_advantage"):
            check_flag(self, name, ImpactEnvError)
        if self.n_steps and self.batch_size and (self.num_envs * self.n_steps) % self.batch_size:
            fail("BcRlConfig.batch_size", self.batch_size, f"a divisor of num_envs x n_steps ({self.num_envs} x "
                 f"{self.n_steps} = {self.num_envs * self.n_steps})", ImpactEnvError)

    def with_horizon(self, horizon_steps: int) -> BcRlConfig:
        """This config with ``n_steps`` and ``batch_size`` filled in for a scenario of ``horizon_steps``."""
        n_steps = self.n_steps or horizon_steps
        divisor = max(d for d in range(1, min(32, n_steps) + 1) if n_steps % d == 0)
        return replace(self, n_steps=n_steps, batch_size=self.batch_size or self.num_envs * divisor)

    @property
    def rollout_frames(self) -> int:
        """Env-steps per rollout (n_steps filled in: :meth:`with_horizon`)."""
        if self.n_steps is None:
            raise ImpactEnvError("BcRlConfig.n_steps is the scenario's horizon: call with_horizon() first")
        return self.num_envs * self.n_steps

    @property
    def chunk_frames(self) -> int:
        """Env-steps between checkpoints: whole rollouts."""
        return -(-self.checkpoint_frames // self.rollout_frames) * self.rollout_frames

    @property
    def warmup_frames(self) -> int:
        """Env-steps of the critic's warm-up."""
        return self.critic_warmup_rollouts * self.rollout_frames

    def world_options(self) -> dict[str, Any]:
        options = {"thrust_noise": self.thrust_noise, "initial_position_noise_m": self.initial_position_noise_m,
                   "reward_mode": self.reward_mode, "fuel_penalty": self.fuel_penalty,
                   "impact_velocity_noise_mps": self.impact_velocity_noise_mps}
        return options | ({} if self.restitution is None else {"restitution": self.restitution})

    def bc_weight_at(self, frames: int) -> float:
        """The BC term's weight in the update after ``frames`` env-steps (0 during the critic's warm-up, when
        the actor does not learn)."""
        if frames <= self.warmup_frames:
            return 0.0
        if self.bc_half_life_frames is None:
            return self.bc_weight
        return self.bc_weight * 0.5 ** ((frames - self.warmup_frames) / self.bc_half_life_frames)


# ------------------------------------------------------------------------------------------------ the inputs
def expert_pairs(cfg: BcRlConfig, scenario_name: str) -> tuple[np.ndarray, np.ndarray]:
    """The expert's (observations (P, obs), actions (P, act)): every label of the DAgger run in ``cfg.policy``
    (its finished rounds), else the Minari dataset of ``scenario_name`` in ``cfg.dataset_dir``."""
    from baselines.bc import load_demonstrations
    from baselines.dagger import load_round

    folder = Path(cfg.policy)
    state = folder / "dagger.json"
    if state.is_file():
        rounds = len(json.loads(state.read_text(encoding="utf-8"))["rounds"])
        episodes = [(e.observations, e.labels) for r in range(rounds) for e in load_round(folder, r)]
    else:
        episodes = load_demonstrations(scenario_name, cfg.dataset_dir)
    if not episodes:
        raise ImpactEnvError(f"no expert pairs for {cfg.policy}: its DAgger run has no finished round")
    return (np.concatenate([o for o, _ in episodes]).astype(np.float32),
            np.concatenate([a for _, a in episodes]).astype(np.float32))


def initial_policy(cfg: BcRlConfig, observation_space: Any, action_space: Any) -> tuple[Any, Any]:
    """(the BC policy's PPO model, its observation statistics), loaded without unpickling, after checking that
    the folder is a central PPO policy of this scenario with its statistics."""
    from baselines.model_files import NORMALIZATION_FILE, load_model, read_normalization, read_train_json
    from baselines.run_meta import check_scenario
    from impact_env.transport.scenario import load_scenario

    folder = Path(cfg.policy)
    if not (folder / "model.zip").is_file():
        raise ImpactEnvError(f"{folder} holds no model.zip: --policy is the run folder of `impact-env bc` or "
                             "`impact-env dagger`")
    meta = read_train_json(folder)
    check_scenario(meta, load_scenario(cfg.scenario), str(folder))
    if meta.get("algo", "ppo") != "ppo" or meta.get("multiagent"):
        raise ImpactEnvError(f"{folder} holds a {meta.get('algo')} policy"
                             f"{' per agent' if meta.get('multiagent') else ''}: BC+RL fine-tunes the central PPO "
                             "policy of `impact-env bc` or `impact-env dagger`")
    if not (folder / NORMALIZATION_FILE).is_file():
        raise ImpactEnvError(f"{folder} has no {NORMALIZATION_FILE}: BC+RL keeps the BC policy's observation "
                             "statistics, so the folder must hold them (impact-env bc and dagger write them)")
    model = load_model(folder / "model.zip", "ppo", observation_space, action_space)
    if model.policy.activation_fn is not torch.nn.Tanh:  # policy_kwargs holding a class would be a pickle
        raise ImpactEnvError(f"{folder}'s policy uses {model.policy.activation_fn.__name__}: BC+RL starts from the "
                             "MlpPolicy of impact-env bc and dagger (tanh)")
    return model, read_normalization(folder / NORMALIZATION_FILE, int(np.prod(observation_space.shape)))


def build(cfg: BcRlConfig, venv_monitor: Any) -> tuple[BCRegularisedPPO, Any]:
    """(the model, its VecNormalize): PPO with the BC policy's architecture and weights (and ``cfg.log_std``),
    over ``venv_monitor`` normalised with the BC policy's frozen observation statistics and a running reward
    normaliser; the expert pairs normalised with the same statistics."""
    from stable_baselines3.common.vec_env import VecNormalize

    from impact_env.transport.scenario import load_scenario

    cfg = cfg.with_horizon(venv_monitor.venv.world.horizon_steps)
    bc, stats = initial_policy(cfg, venv_monitor.observation_space, venv_monitor.action_space)
    venv = VecNormalize(venv_monitor, gamma=cfg.gamma, norm_obs=stats.norm_obs, clip_obs=stats.clip_obs,
                        epsilon=stats.epsilon)
    frozen = FrozenStatistics(shape=stats.mean.shape)
    frozen.mean, frozen.var, frozen.count = stats.mean.copy(), stats.var.copy(), stats.count
    venv.obs_rms = frozen  # type: ignore[assignment]  # SB3 types it for Dict spaces too; a Box has one
    obs, act = expert_pairs(cfg, load_scenario(cfg.scenario).name)
    model = BCRegularisedPPO(
        "MlpPolicy", venv, config=cfg, expert_obs=stats.apply(obs), expert_actions=act, n_steps=cfg.n_steps,
        batch_size=cfg.batch_size, n_epochs=cfg.n_epochs, learning_rate=cfg.lr, gamma=cfg.gamma,
        gae_lambda=cfg.gae_lambda, clip_range=cfg.clip_range, ent_coef=cfg.ent_coef,
        normalize_advantage=cfg.normalize_advantage, seed=cfg.seed, device="cpu",
        verbose=0, policy_kwargs={"net_arch": bc.policy.net_arch})
    model.policy.load_state_dict(bc.policy.state_dict())
    if cfg.log_std is not None:
        with torch.no_grad():
            model.policy.log_std.fill_(cfg.log_std)
    return model, venv


# -------------------------------------------------------------------------------------------------------- run
FREE = ("frames", "checkpoint_frames", "eval_episodes", "eval_batched_world", "threads")
"""Config fields a resumed run may change (they change nothing of the training so far)."""


def run(cfg: BcRlConfig, out: Path, progress: bool = True) -> dict:
    """Fine-tune (or resume) one run in ``out``; returns its result (also ``out``/result.json). Besides
    :mod:`baselines.batched.sb3_ppo`'s files the folder holds ``init_evaluation.json`` (the BC policy flown
    before training, on the result's episode seeds) and ``updates.jsonl`` (one line per PPO update: the BC
    weight and loss, PPO's losses and the policy's action error on expert pairs)."""
    from impact_env.transport.core import TransportCore

    result_path = out / "result.json"
    if result_path.exists():
        return json.loads(result_path.read_text(encoding="utf-8"))
    torch.set_num_threads(cfg.threads)
    cfg = cfg.with_horizon(TransportCore(cfg.scenario).horizon_steps)
    out.mkdir(parents=True, exist_ok=True)
    fix_run_settings(out, json.loads(json.dumps(asdict(cfg))), FREE)
    curve, updates, state_path = out / "curve.jsonl", out / "updates.jsonl", out / "state.json"
    start = time.perf_counter()
    model, venv = build(cfg, make_venv(cfg))
    wall_before = resume_run(model, venv, out, [curve, updates], progress)
    model.updates_log = updates
    init_path = out / "init_evaluation.json"
    if not init_path.exists():  # the BC policy, before any update, on the result's episodes
        init = evaluate(model, venv, cfg, cfg.eval_episodes, batched_world=cfg.eval_batched_world)
        init["expert_action_mse"] = model.expert_action_mse()
        write_atomic(init_path, json.dumps(init, indent=1))
        if progress:
            print(f"{out.name}: the BC policy succeeds in {100 * init['pymunk']['success_rate']:.0f} % of "
                  f"{cfg.eval_episodes} pymunk episodes", flush=True)
    setup_s = time.perf_counter() - start
    meta = {"method": "BC+RL", "normalized": True, "init_policy": str(cfg.policy), "bc_weight": cfg.bc_weight,
            "bc_half_life_frames": cfg.bc_half_life_frames, "critic_warmup_rollouts": cfg.critic_warmup_rollouts,
            "expert_pairs": len(model.expert_obs)}
    callback = curve_callback(curve, wall_before)
    learn_in_chunks(model, cfg, callback,
                    lambda wall: save_checkpoint(model, venv, cfg, out, wall, trainer=TRAINER, meta=meta), out,
                    progress, note=lambda: f", BC weight {cfg.bc_weight_at(model.num_timesteps):.3g}, expert action "
                                           f"error {model.expert_action_mse():.2e}")
    train_wall = json.loads(state_path.read_text(encoding="utf-8"))["wall_s"]
    start = time.perf_counter()
    venv.training = False
    evaluation = evaluate(model, venv, cfg, cfg.eval_episodes, batched_world=cfg.eval_batched_world)
    evaluation["expert_action_mse"] = model.expert_action_mse()
    result = {"kind": "sb3", "algorithm": "bc_rl", "task": cfg.scenario, "seed": cfg.seed,
              "env_steps": int(model.num_timesteps), "budget_env_steps": cfg.frames,
              "wall_s": round(float(train_wall), 1), "setup_s_last_start": round(setup_s, 1),
              "eval_s": round(time.perf_counter() - start, 1),
              "env_steps_per_s": round(model.num_timesteps / max(float(train_wall), 1e-9), 1),
              "expert_pairs": len(model.expert_obs),
              "evaluation_init": json.loads(init_path.read_text(encoding="utf-8")), "evaluation": evaluation,
              "config": asdict(cfg), "threads": cfg.threads}
    write_atomic(result_path, json.dumps(result, indent=1))
    return result
