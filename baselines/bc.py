"""Behaviour cloning from the expert's Minari dataset: ``impact-env bc SCENARIO --dataset DIR``.

The third learned baseline: a stable-baselines3 PPO ``MlpPolicy`` (the architecture of ``ppo.yml``) is fitted
to the expert's (observation, action) pairs by maximising the log-likelihood of the expert's actions under
the policy's Gaussian, with a small entropy bonus, minibatch Adam, and a held-out share of episodes to
report validation error and keep the epoch that imitates the held-out episodes best. The result is saved
like any trained model (``model.zip``, ``vecnormalize.json`` with the dataset's observation statistics,
``train.json``), so ``impact-env run --controller`` and ``impact-env bench`` fly it unchanged.

Why a loop of our own instead of the ``imitation`` library's BC: ``pip install imitation`` (1.0.1) would
replace this package's gymnasium 1.x with 0.29.1 and stable-baselines3 with 2.2.1. The loop below is the
same objective (negative log-likelihood plus entropy weight) in a few dozen lines.
"""

from __future__ import annotations

import copy
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from baselines.model_files import LEGACY_NORMALIZATION_FILE, NORMALIZATION_FILE, save_normalization, set_obs_statistics
from baselines.record import dataset_id, datasets_path, use_datasets_path
from baselines.run_folder import check_run_folder, run_folder_path
from baselines.run_meta import scenario_fingerprint
from impact_env.config_checks import check_flag, check_integer, check_number, check_text, check_widths
from impact_env.errors import ImpactEnvError
from impact_env.results_store import atomic_path, check_output_folder, write_atomic
from impact_env.transport.scenario import Scenario, load_scenario

Episode = tuple[np.ndarray, np.ndarray]
"""One episode's (observations (T, obs), actions (T, act))."""
T = TypeVar("T")

MIN_OBS_STD = 1e-2  # features constant in the demonstrations (e.g. a passive disc's heading) are not blown up


@dataclass(frozen=True)
class BCConfig:
    """What ``impact-env bc SCENARIO`` fits, and how (see the module docstring)."""

    scenario: str
    """The scenario whose expert dataset is cloned (a shipped name or a scenario file)."""
    dataset_dir: str | None = None
    """Where the Minari dataset is; None: Minari's own folder (see :mod:`baselines.record`)."""
    epochs: int = 30
    """Passes over the training episodes."""
    batch_size: int = 256
    """Observation-action pairs per Adam step."""
    learning_rate: float = 1e-3
    """Adam's learning rate."""
    ent_weight: float = 1e-3
    """Weight of the entropy bonus, against the negative log-likelihood."""
    validation_share: float = 0.1
    """Share of the episodes held out (in [0, 1]; at least one when there are two or more, never all)."""
    seed: int = 0
    """Seed of the policy and the minibatches."""
    out: str | None = None
    """The run folder; None: ``<runs_dir>/bc_<scenario>_s<seed>``."""
    runs_dir: str = "runs"
    """The parent of the default run folder."""
    net_arch: tuple[int, ...] = (128, 128)
    """Hidden layer sizes of the policy and value networks."""
    quiet: bool = False
    """No line per epoch (``--quiet``)."""

    def __post_init__(self) -> None:
        check_text(self, "scenario", ImpactEnvError)
        check_text(self, "dataset_dir", ImpactEnvError, none="Minari's own folder")
        check_fit_fields(self)
        check_run_folder(self, "bc_<scenario>_s<seed>")


def check_fit_fields(config: Any) -> None:
    """Check the fields of the fit that :class:`BCConfig` and the DAgger config share (``epochs``,
    ``batch_size``, ``learning_rate``, ``ent_weight``, ``validation_share``, ``seed``, ``net_arch``, ``quiet``)."""
    for name in ("epochs", "batch_size"):
        check_integer(config, name, ImpactEnvError, low=1)
    check_number(config, "learning_rate", ImpactEnvError, low=0, low_open=True)
    check_number(config, "ent_weight", ImpactEnvError, low=0)
    check_number(config, "validation_share", ImpactEnvError, low=0, high=1)
    check_integer(config, "seed", ImpactEnvError, low=0)
    check_flag(config, "quiet", ImpactEnvError)
    check_widths(config, "net_arch", ImpactEnvError, lists=True)


def load_demonstrations(scenario_name: str,
                        dataset_dir: str | Path | None = None) -> list[Episode]:
    """The (observations, actions) of every episode of ``impact_env/<scenario>/expert-v0`` in ``dataset_dir``
    (default: Minari's own folder)."""
    use_datasets_path(dataset_dir)
    import minari

    name = dataset_id(scenario_name)
    if name not in minari.list_local_datasets():
        where = "" if dataset_dir is None else f" --out {dataset_dir}"
        raise ImpactEnvError(f"no dataset {name!r} in {datasets_path(dataset_dir)}: record one with "
                             f"`impact-env record {scenario_name}{where}`")
    return [(np.asarray(ep.observations[:-1], dtype=np.float32), np.asarray(ep.actions, dtype=np.float32))
            for ep in minari.load_dataset(name).iterate_episodes()]


def split_episodes(episodes: list[T], validation_share: float) -> tuple[list[T], list[T]]:
    """(training, held-out) episodes: the last ``validation_share`` of them held out, at least one when there are
    two or more and the share is > 0, never all."""
    n_val = int(round(validation_share * len(episodes))) if len(episodes) > 1 else 0
    n_val = min(max(n_val, 1 if validation_share > 0 and len(episodes) > 1 else 0), len(episodes) - 1)
    return episodes[:len(episodes) - n_val], episodes[len(episodes) - n_val:]


@dataclass
class FittedPolicy:
    """What :func:`fit_policy` returns: the SB3 model, its observation normaliser and the fit's record."""

    model: Any
    """The stable-baselines3 PPO whose policy was fitted."""
    venv: Any
    """The VecNormalize holding the demonstrations' observation statistics."""
    history: list[dict[str, Any]]
    """One row per epoch: ``nll``, ``train_mse`` and, with held-out episodes, ``val_mse``."""
    kept_epoch: int
    """The epoch whose weights were kept (the lowest validation error; the last without held-out episodes)."""
    val_mse: float | None
    """The kept epoch's validation error (None without held-out episodes)."""
    samples: int
    """Training (observation, action) pairs."""
    zero_action_mse: float
    """Mean squared training action: the error of doing nothing, the scale ``train_mse`` reads against."""
    wall_time_s: float
    """Seconds the fit took."""


def fit_policy(scenario: Scenario, train_eps: list[Episode], val_eps: list[Episode], *, epochs: int = 30,
               batch_size: int = 256, learning_rate: float = 1e-3, ent_weight: float = 1e-3, seed: int = 0,
               net_arch: tuple[int, ...] = (128, 128), quiet: bool = False) -> FittedPolicy:
    """Fit a fresh PPO ``MlpPolicy`` to ``train_eps`` (the module docstring's loop), keeping the epoch that
    imitates ``val_eps`` best. Every episode is (observations (T, obs), actions (T, act)) of ``scenario``'s
    central env. The loop of ``impact-env bc`` and of each DAgger round (:mod:`baselines.dagger`)."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    from impact_env.transport.gym_env import TransportEnv

    if not train_eps:
        raise ImpactEnvError("behaviour cloning needs at least one training episode")
    obs = np.concatenate([o for o, _ in train_eps])
    act = np.concatenate([a for _, a in train_eps])
    expected = TransportEnv(scenario)
    if obs.shape[1:] != expected.observation_space.shape or act.shape[1:] != expected.action_space.shape:
        raise ImpactEnvError(f"dataset shapes {obs.shape[1:]}, {act.shape[1:]} do not match the {scenario.name} env's "
                             f"{expected.observation_space.shape}, {expected.action_space.shape}")

    venv = VecNormalize(DummyVecEnv([lambda: TransportEnv(scenario)]), norm_reward=False)
    set_obs_statistics(venv, obs.mean(axis=0).astype(np.float64),
                       np.maximum(obs.var(axis=0), MIN_OBS_STD ** 2).astype(np.float64), float(len(obs)))
    model = PPO("MlpPolicy", venv, seed=seed, device="cpu",
                policy_kwargs={"net_arch": list(net_arch), "log_std_init": -0.5})
    policy = model.policy
    policy.set_training_mode(True)
    # one thread: the minibatches of a 128-wide MLP are too small to share, and on a busy machine a second
    # thread's synchronisation made a 30-epoch fit of 2,000 samples 60 times slower (31 s against 0.5 s)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        return _fit_loop(policy, model, venv, obs, act, val_eps, epochs, batch_size, learning_rate, ent_weight, seed,
                         quiet)
    finally:
        torch.set_num_threads(threads)


def _fit_loop(policy: Any, model: Any, venv: Any, obs: np.ndarray, act: np.ndarray, val_eps: list[Episode],
              epochs: int, batch_size: int, learning_rate: float, ent_weight: float, seed: int,
              quiet: bool) -> FittedPolicy:
    import torch

    optimiser = torch.optim.Adam(policy.parameters(), lr=learning_rate)

    def tensors(o: np.ndarray, a: np.ndarray):
        return torch.as_tensor(venv.normalize_obs(o), dtype=torch.float32), torch.as_tensor(a, dtype=torch.float32)

    obs_t, act_t = tensors(obs, act)
    val = tensors(np.concatenate([o for o, _ in val_eps]), np.concatenate([a for _, a in val_eps])) if val_eps else None
    rng = np.random.default_rng(seed)
    start = time.perf_counter()
    history: list[dict[str, Any]] = []
    best: tuple[float, dict[str, Any] | None, int] = (float("inf"), None, 0)  # (validation error, weights, epoch)
    for epoch in range(1, epochs + 1):
        order = torch.as_tensor(rng.permutation(len(obs_t)))
        total = 0.0
        for k in range(0, len(order), batch_size):
            idx = order[k:k + batch_size]
            _, log_prob, entropy = policy.evaluate_actions(obs_t[idx], act_t[idx])
            # SB3's PPO: without a closed-form entropy (not the case of a Gaussian policy), -log_prob estimates it
            entropy_mean = entropy.mean() if entropy is not None else (-log_prob).mean()
            loss = -log_prob.mean() - ent_weight * entropy_mean
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
            total += loss.item() * len(idx)
        row = {"epoch": epoch, "nll": total / len(order), "train_mse": _action_mse(policy, obs_t, act_t)}
        if val is not None:
            row["val_mse"] = _action_mse(policy, *val)
            if row["val_mse"] < best[0]:
                best = (row["val_mse"], copy.deepcopy(policy.state_dict()), epoch)
        history.append(row)
        if not quiet:
            print(f"  epoch {epoch}/{epochs}: " + ", ".join(f"{k} {v:.3g}" for k, v in row.items()
                                                          if k != "epoch"), flush=True)
    if best[1] is not None:  # keep the weights that imitated the held-out episodes best
        policy.load_state_dict(best[1])
        if not quiet:
            print(f"  kept epoch {best[2]} (lowest validation error {best[0]:.3g})")
    policy.set_training_mode(False)
    return FittedPolicy(model, venv, history, best[2] or epochs, best[0] if best[1] is not None else None, len(obs),
                        float((act ** 2).mean()), time.perf_counter() - start)


def save_policy(fitted: FittedPolicy, run_dir: Path, meta: dict[str, Any]) -> None:
    """Write ``model.zip``, ``vecnormalize.json`` and ``train.json`` (``meta``, which must say ``algo`` and
    ``normalized``) to ``run_dir``: the folder ``impact-env run --controller run_dir/model.zip`` flies."""
    with atomic_path(run_dir / "model.zip") as tmp:
        fitted.model.save(tmp)
    save_normalization(fitted.venv, run_dir / NORMALIZATION_FILE)
    (run_dir / LEGACY_NORMALIZATION_FILE).unlink(missing_ok=True)  # a stale pickle must not sit beside the model
    write_atomic(run_dir / "train.json", json.dumps(meta, indent=2))


def behaviour_clone(config: BCConfig) -> Path:
    """Fit a policy to the expert's demonstrations and save it; returns the run directory."""
    scenario = load_scenario(config.scenario)
    run_dir = run_folder_path(config.out, config.runs_dir, f"bc_{scenario.name}_s{config.seed}")
    check_output_folder(run_dir, "--out")  # before any epoch
    episodes = load_demonstrations(scenario.name, config.dataset_dir)
    train_eps, val_eps = split_episodes(episodes, config.validation_share)
    fitted = fit_policy(scenario, train_eps, val_eps, epochs=config.epochs, batch_size=config.batch_size,
                        learning_rate=config.learning_rate, ent_weight=config.ent_weight, seed=config.seed,
                        net_arch=config.net_arch, quiet=config.quiet)
    save_policy(fitted, run_dir, {
        "algo": "ppo", "method": "behaviour cloning", "normalized": True, "scenario": scenario.name,
        "scenario_fingerprint": scenario_fingerprint(scenario),
        "dataset": dataset_id(scenario.name), "episodes_train": len(train_eps), "episodes_validation": len(val_eps),
        "samples": fitted.samples, "epochs": config.epochs, "batch_size": config.batch_size,
        "learning_rate": config.learning_rate, "ent_weight": config.ent_weight, "seed": config.seed,
        "multiagent": False, "kept_epoch": fitted.kept_epoch, "zero_action_mse": fitted.zero_action_mse,
        "history": fitted.history, "wall_time_s": fitted.wall_time_s})
    fitted.venv.close()
    return run_dir


def _action_mse(policy: Any, obs, act) -> float:
    """Mean squared error of the deterministic action (the Gaussian's mean, clipped as ``predict`` does)."""
    import torch

    with torch.no_grad():
        mean = policy.get_distribution(obs).distribution.mean.clamp(-1.0, 1.0)
    return float(((mean - act) ** 2).mean())
