"""PPO with a behaviour-cloning term in its loss: the update of BC+RL (:mod:`baselines.batched.bc_rl`).

:class:`BCRegularisedPPO` is stable-baselines3's PPO whose every gradient step adds
``weight * -log pi(a_expert | s_expert)`` on a minibatch of the expert's (observation, action) pairs, the BC term
of DAPG (Rajeswaran et al. 2018), and whose actor does not learn while the critic warms up. Its ``train`` is
a copy of ``PPO.train`` (SB3 2.x; Box actions, no value clipping, no target KL) rather than a wrapper, because
the BC term must enter the same gradient step as PPO's loss (one optimiser step, one gradient-norm clip) and
SB3 has no hook there; with weight 0 and no warm-up it gives SB3's weights exactly (a test checks it). The
expert pairs are kept out of ``model.zip``, which stays the pickle-free folder ``impact-env run`` flies.
:class:`FrozenStatistics` keeps a VecNormalize's observation statistics fixed: the BC policy's weights were
fitted to them.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.running_mean_std import RunningMeanStd
from torch.nn import functional as F

MSE_PAIRS = 2048  # expert pairs of the logged action error (the same ones at every update)


class BcTerm(Protocol):
    """What the update reads of its config (:class:`~baselines.batched.bc_rl.BcRlConfig`)."""

    @property
    def seed(self) -> int: ...

    @property
    def bc_batch_size(self) -> int: ...

    @property
    def warmup_frames(self) -> int: ...

    def bc_weight_at(self, frames: int) -> float: ...


class FrozenStatistics(RunningMeanStd):
    """Observation statistics that training does not update: the BC policy's weights were fitted to them."""

    def update(self, arr: np.ndarray) -> None:
        pass


class BCRegularisedPPO(PPO):
    """SB3's PPO whose loss adds ``weight * -log pi(a_expert | s_expert)`` on a minibatch of expert pairs at every
    gradient step, and whose actor does not learn during the critic's warm-up.

    ``expert_obs`` (P, obs) are already normalised with the policy's frozen statistics; ``expert_actions`` (P,
    act). ``config`` is a :class:`~baselines.batched.bc_rl.BcRlConfig`: its ``bc_weight_at`` gives the weight of
    each update, ``warmup_frames`` the critic's warm-up. ``updates_log``, when set, gets one JSON line per update.
    """

    def __init__(self, *args: Any, config: BcTerm, expert_obs: np.ndarray, expert_actions: np.ndarray,
                 **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.bc_config = config
        self.expert_obs = torch.as_tensor(expert_obs, dtype=torch.float32)
        self.expert_actions = torch.as_tensor(expert_actions, dtype=torch.float32)
        pick = np.random.default_rng(0).permutation(len(expert_obs))[:MSE_PAIRS]
        self.mse_pairs = (self.expert_obs[pick], self.expert_actions[pick])
        self.updates_log: Path | None = None

    def _excluded_save_params(self) -> list[str]:
        # not pickled into model.zip: a model folder holds no pickle it cannot rebuild (baselines/model_files.py)
        return [*super()._excluded_save_params(), "bc_config", "expert_obs", "expert_actions", "mse_pairs",
                "updates_log"]

    def expert_action_mse(self) -> float:
        """Mean squared error of the deterministic action (clipped) against the expert's, on fixed expert pairs."""
        obs, act = self.mse_pairs
        with torch.no_grad():
            mean = self.policy.get_distribution(obs).mode().clamp(-1.0, 1.0)  # a Gaussian's mode: its mean
        return float(((mean - act) ** 2).mean())

    def train(self) -> None:
        self.policy.set_training_mode(True)
        self._update_learning_rate(self.policy.optimizer)
        clip_range = self.clip_range(self._current_progress_remaining)  # type: ignore[operator]
        cfg = self.bc_config
        warmup = self.num_timesteps <= cfg.warmup_frames
        weight = cfg.bc_weight_at(self.num_timesteps)
        rng = np.random.default_rng([cfg.seed, self.num_timesteps])  # the same minibatches after a resume
        rows: dict[str, list[float]] = {"policy_loss": [], "value_loss": [], "bc_nll": [], "clip_fraction": []}
        for _ in range(self.n_epochs):
            for data in self.rollout_buffer.get(self.batch_size):
                values, log_prob, entropy = self.policy.evaluate_actions(data.observations, data.actions)
                values = values.flatten()
                advantages = data.advantages
                if self.normalize_advantage and len(advantages) > 1:
                    advantages = (advantages - advantages.mean()) / (advantages.std() + 1e-8)
                ratio = torch.exp(log_prob - data.old_log_prob)
                policy_loss = -torch.min(advantages * ratio,
                                         advantages * torch.clamp(ratio, 1 - clip_range, 1 + clip_range)).mean()
                value_loss = F.mse_loss(data.returns, values)
                entropy_loss = -torch.mean(-log_prob) if entropy is None else -torch.mean(entropy)
                if warmup:
                    loss = self.vf_coef * value_loss
                else:  # PPO.train's sum, in its order (the same floats with weight 0)
                    loss = policy_loss + self.ent_coef * entropy_loss + self.vf_coef * value_loss
                if weight > 0:
                    idx = torch.as_tensor(rng.integers(0, len(self.expert_obs), size=cfg.bc_batch_size))
                    bc_nll = -self.policy.get_distribution(self.expert_obs[idx]).log_prob(self.expert_actions[idx])
                    loss = loss + weight * bc_nll.mean()
                    rows["bc_nll"].append(bc_nll.mean().item())
                rows["policy_loss"].append(policy_loss.item())
                rows["value_loss"].append(value_loss.item())
                rows["clip_fraction"].append(torch.mean((torch.abs(ratio - 1) > clip_range).float()).item())
                self.policy.optimizer.zero_grad()
                loss.backward()
                torch.nn.utils.clip_grad_norm_(self.policy.parameters(), self.max_grad_norm)
                self.policy.optimizer.step()
            self._n_updates += 1
        if self.updates_log is not None:
            row = {"frames": int(self.num_timesteps), "warmup": warmup, "bc_weight": weight,
                   **{k: (float(np.mean(v)) if v else None) for k, v in rows.items()},
                   "expert_action_mse": self.expert_action_mse(),
                   "log_std_mean": float(self.policy.log_std.detach().mean())}
            with self.updates_log.open("a", encoding="utf-8") as f:
                f.write(json.dumps(row) + "\n")
