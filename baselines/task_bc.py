"""Behaviour cloning of the expert on a family's generated tasks: one goal-conditioned policy per family.

    run = train_task_bc(TaskBCConfig("gaps", datasets_dir="datasets", seed=0))
    policy = TaskBCPolicy.load(run)                       # acts on TaskObservation's padded layout

The policy is a plain torch MLP (``hidden`` layers, tanh, a tanh output in [-1, 1]) from the padded
observation (:class:`impact_env.transport.task_observation.TaskObservation`: bodies, time left, the task's
regions and windows, the obstacles) to the padded action, fitted to the training dataset
``impact_env/generated_<family>/expert-v0`` (:mod:`baselines.task_dataset`) by mean squared error with Adam on
minibatches. Observations are standardised with the dataset's mean and standard deviation (features
constant in the data, such as absent slots, keep a unit scale), and ``observation_noise`` adds Gaussian
noise of that many standard deviations to each training observation (the states the expert never visits).
A deterministic regressor rather than stable-baselines3's Gaussian policy of :mod:`baselines.bc`: the
expert is deterministic, the policy is flown deterministically, and the saved file is a state dict with
its normalisation, loadable without pickles. The ``imitation`` library is not used: its 1.0.1 pins
gymnasium 0.29 and stable-baselines3 2.2, which this package's gymnasium 1.x excludes.

``run/policy.pt`` holds the weights, the normalisation and the layout; ``run/train.json`` the
configuration, dataset size (its environment steps are the training budget: BC takes no new ones), epochs,
final training loss (the last epoch's, on noisy observations), the fit's mean squared error on the clean
training steps (``train_mse``) and wall time.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from impact_env.config_checks import check_integer, check_number, check_text, check_widths
from impact_env.errors import ImpactEnvError

__all__ = ["TaskBCConfig", "TaskBCPolicy", "train_task_bc"]

MIN_STD = 1e-2


@dataclass(frozen=True)
class TaskBCConfig:
    """What :func:`train_task_bc` fits, and how."""

    family: str
    """The task family whose training dataset is cloned."""
    datasets_dir: str | None = None
    """Where the Minari datasets are (``impact-env dataset --out``); None: Minari's own folder."""
    epochs: int = 40
    """Passes over the training steps."""
    batch_size: int = 512
    """Observation-action pairs per Adam step."""
    learning_rate: float = 1e-3
    """Adam's learning rate."""
    hidden: tuple[int, ...] = (256, 256)
    """Widths of the hidden layers."""
    observation_noise: float = 0.05
    """Standard deviation of the Gaussian noise added to standardised training observations."""
    seed: int = 0
    """Seed of the weights, the minibatches and the noise."""
    out: str = "runs/task_bc"
    """The run folder."""

    def __post_init__(self) -> None:
        check_text(self, "family", ImpactEnvError)
        check_text(self, "datasets_dir", ImpactEnvError, none="Minari's own folder")
        check_integer(self, "epochs", ImpactEnvError, low=1)
        check_integer(self, "batch_size", ImpactEnvError, low=1)
        check_number(self, "learning_rate", ImpactEnvError, low=0, low_open=True)
        check_widths(self, "hidden", ImpactEnvError)
        check_number(self, "observation_noise", ImpactEnvError, low=0)
        check_integer(self, "seed", ImpactEnvError, low=0)
        check_text(self, "out", ImpactEnvError)


def _network(n_in: int, n_out: int, hidden: tuple[int, ...]):
    import torch

    layers, width = [], n_in
    for h in hidden:
        layers += [torch.nn.Linear(width, h), torch.nn.Tanh()]
        width = h
    layers += [torch.nn.Linear(width, n_out), torch.nn.Tanh()]
    return torch.nn.Sequential(*layers)


def _load_steps(dataset_id: str, datasets_dir: str | None) -> tuple[np.ndarray, np.ndarray, int]:
    from baselines.record import use_datasets_path

    use_datasets_path(datasets_dir)
    import minari

    if dataset_id not in minari.list_local_datasets():
        raise ImpactEnvError(f"no dataset {dataset_id!r} in {datasets_dir or 'Minari’s folder'}: build it first "
                             "(impact-env dataset --family F --tasks DIR --out DIR)")
    obs, act, episodes = [], [], 0
    for ep in minari.load_dataset(dataset_id).iterate_episodes():
        obs.append(np.asarray(ep.observations[:-1], dtype=np.float32))
        act.append(np.asarray(ep.actions, dtype=np.float32))
        episodes += 1
    return np.concatenate(obs), np.concatenate(act), episodes


def train_task_bc(config: TaskBCConfig) -> Path:
    """Fit the policy (see the module docstring); returns the run folder."""
    import torch

    from baselines.task_dataset import dataset_ids

    start = time.perf_counter()
    obs, act, episodes = _load_steps(dataset_ids(config.family)[0], config.datasets_dir)
    mean = obs.mean(axis=0)
    std = np.maximum(obs.std(axis=0), MIN_STD)
    torch.manual_seed(config.seed)
    gen = torch.Generator().manual_seed(config.seed)
    net = _network(obs.shape[1], act.shape[1], config.hidden)
    opt = torch.optim.Adam(net.parameters(), lr=config.learning_rate)
    x = torch.as_tensor((obs - mean) / std)
    y = torch.as_tensor(act)
    loss_value = float("nan")
    for _ in range(config.epochs):
        order = torch.randperm(len(x), generator=gen)
        total = 0.0
        for i in range(0, len(x), config.batch_size):
            idx = order[i:i + config.batch_size]
            xb = x[idx]
            if config.observation_noise > 0:
                xb = xb + config.observation_noise * torch.randn(xb.shape, generator=gen)
            loss = torch.mean((net(xb) - y[idx]) ** 2)
            opt.zero_grad()
            loss.backward()
            opt.step()
            total += loss.item() * len(idx)
        loss_value = total / len(x)
    with torch.no_grad():  # the fit without the training noise, over every step
        train_mse = float(torch.mean((net(x) - y) ** 2))
    out = Path(config.out)
    out.mkdir(parents=True, exist_ok=True)
    torch.save({"state_dict": net.state_dict(), "mean": torch.as_tensor(mean), "std": torch.as_tensor(std),
                "hidden": list(config.hidden), "n_in": int(obs.shape[1]), "n_out": int(act.shape[1]),
                "family": config.family}, out / "policy.pt")
    (out / "train.json").write_text(json.dumps({
        "config": asdict(config), "episodes": episodes, "steps": int(len(obs)), "final_loss": loss_value,
        "train_mse": train_mse,
        "wall_s": time.perf_counter() - start}, indent=1))
    return out


class TaskBCPolicy:
    """A policy saved by :func:`train_task_bc`, as a controller of a
    :class:`~impact_env.transport.task_observation.TaskConditioned` env (``reset`` and ``act``)."""

    name = "task_bc"

    def __init__(self, payload: dict[str, Any]) -> None:
        net = _network(payload["n_in"], payload["n_out"], tuple(payload["hidden"]))
        net.load_state_dict(payload["state_dict"])
        # the forward pass in numpy: a few small matrix products, without torch's per-call and thread overhead
        self.layers = [(m.weight.detach().numpy().astype(np.float32).T.copy(),
                        m.bias.detach().numpy().astype(np.float32).copy()) for m in net if hasattr(m, "weight")]
        self.mean = payload["mean"].numpy().astype(np.float32)
        self.std = payload["std"].numpy().astype(np.float32)
        self.family = payload["family"]

    @classmethod
    def load(cls, run: str | Path) -> TaskBCPolicy:
        import torch

        path = Path(run) / "policy.pt"
        if not path.is_file():
            raise ImpactEnvError(f"{run} has no policy.pt: train it first (baselines.task_bc.train_task_bc)")
        return cls(torch.load(path, weights_only=True))  # tensors and plain types only: no code runs

    def reset(self, env: Any = None, seed: int | None = None) -> None:
        pass

    def act(self, observation: np.ndarray, info: dict[str, Any] | None = None) -> np.ndarray:
        x = (np.asarray(observation, dtype=np.float32) - self.mean) / self.std
        for w, b in self.layers:  # every layer, the output one too, is tanh(x W + b)
            x = np.tanh(x @ w + b)
        return x
