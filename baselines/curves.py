"""Learning curves of training runs: ``impact-env curves RUN_DIR [RUN_DIR ...] --out curves.png``.

Reads each run's periodic evaluations (``eval/evaluations.npz``, written by ``impact-env train``; their
returns are the task's final STL robustness) and its ``train.json``, and plots mean +- std robustness and
the success rate against environment steps, one line per run.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from baselines.model_files import read_train_json
from impact_env.errors import ImpactEnvError, ModelFileError


@dataclass
class Curve:
    label: str
    meta: dict  # the run's train.json
    timesteps: np.ndarray  # (n,)
    robustness: np.ndarray  # (n, episodes per evaluation)
    success: np.ndarray  # (n,) share of evaluation episodes with robustness > 0


def load_curve(run_dir: str | Path) -> Curve:
    run = Path(run_dir)
    path = run / "eval" / "evaluations.npz"
    if not path.is_file():
        raise ImpactEnvError(f"{run} has no evaluations ({path} is missing): is it an `impact-env train` run "
                             "that reached its first evaluation?")
    try:  # allow_pickle stays False: an object array in the file is refused, not unpickled
        with np.load(path, allow_pickle=False) as data:
            timesteps, rho = np.asarray(data["timesteps"]), np.asarray(data["results"], dtype=float)
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ModelFileError(f"{path} is not an evaluations file written by impact-env train: "
                             f"{str(exc)[:200]}") from None
    if rho.ndim != 2 or timesteps.shape != (len(rho),):
        raise ModelFileError(f"{path}: results must have shape (evaluations, episodes) and timesteps one entry per "
                             f"evaluation, got {rho.shape} and {timesteps.shape}")
    meta = read_train_json(run)
    mode = meta.get("env_options", {}).get("reward_mode", "dense")
    label = f"{meta.get('algo', run.name)} ({mode})" if meta else run.name
    if meta.get("engine") == "rllib":  # impact-env train ... --engine rllib
        label = f"RLlib {meta.get('algo', 'ppo')}, {meta.get('policies', '?')} policies ({mode})"
    return Curve(label, meta, timesteps, rho, (rho > 0).mean(axis=1))


def training_table(curves: list[Curve]) -> str:
    """Markdown: per run, the steps trained, the wall clock, and the first, last and best evaluations."""
    lines = ["| run | scenario | steps trained | wall clock (min) | first success at (steps) | last evaluation (m) | "
             "best evaluation (m) |", "|---|---|---:|---:|---:|---:|---:|"]
    for c in curves:
        mean = c.robustness.mean(axis=1)
        ok = np.flatnonzero(c.success > 0)
        steps = c.meta.get("timesteps_trained", c.timesteps[-1])
        wall = c.meta.get("wall_time_s")
        lines.append(f"| {c.label} | {c.meta.get('scenario', '?')} | {steps:,} | "
                     f"{'?' if wall is None else f'{wall / 60:.0f}'} | "
                     f"{f'{c.timesteps[ok[0]]:,}' if len(ok) else 'never'} | {mean[-1]:+.3f} | {mean.max():+.3f} |")
    return "\n".join(lines)


def plot_curves(curves: list[Curve], path: str | Path, title: str = "") -> None:
    from matplotlib.figure import Figure
    from matplotlib.ticker import FuncFormatter

    fig = Figure(figsize=(10, 3.6), layout="constrained")
    ax_rho, ax_ok = fig.subplots(1, 2)
    for c in curves:
        mean, std = c.robustness.mean(axis=1), c.robustness.std(axis=1)
        (line,) = ax_rho.plot(c.timesteps, mean, marker="o", ms=3, label=c.label)
        ax_rho.fill_between(c.timesteps, mean - std, mean + std, color=line.get_color(), alpha=0.2)
        ax_ok.plot(c.timesteps, 100 * c.success, marker="o", ms=3, color=line.get_color(), label=c.label)
    ax_rho.axhline(0.0, color="k", lw=0.8)
    ax_rho.set(xlabel="environment steps", ylabel="evaluation robustness (m)", title=title or "robustness")
    ax_ok.set(xlabel="environment steps", ylabel="success (%)", ylim=(-5, 105), title="success rate")
    for ax in (ax_rho, ax_ok):  # 400000 -> 400k: full numbers overlap under a few ticks
        ax.xaxis.set_major_formatter(FuncFormatter(_steps_label))
    ax_rho.legend(fontsize=8)
    from impact_env.results_store import atomic_path

    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=100)


def _steps_label(x: float, _pos: int) -> str:
    if abs(x) >= 1e6:
        return f"{x / 1e6:g}M"
    return f"{x / 1e3:g}k" if abs(x) >= 1e3 else f"{x:g}"

