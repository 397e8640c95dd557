"""stable-baselines3 callbacks of ``impact-env train``: progress, task metrics in TensorBoard, evaluation.

- :func:`progress_callback`: on a terminal a progress bar whose total is what will really be trained (PPO
  trains whole rollouts, so 5,000 requested steps of ``n_steps = 4096`` on 2 envs are 8,192); otherwise, when the
  output goes to a file or a pipe, one plain line per rollout at most every ``period_s`` seconds, and a last one.
- :func:`task_metrics_callback`: the task's own numbers of every finished training episode, as TensorBoard
  scalars ``rollout/robustness`` (m), ``rollout/success_rate``, ``rollout/fuel_Ns`` and ``rollout/impacts``
  (robot-object impacts per episode), averaged over the episodes between two log dumps.
- :func:`evaluation_callback`: SB3's ``EvalCallback`` that also logs ``eval/robustness``, ``eval/fuel_Ns`` and
  ``eval/impacts`` (SB3 logs ``eval/success_rate`` from ``info["is_success"]``), keeps the evaluations of a run
  that is resumed, and evaluates once more at the end of training if the last evaluation was earlier, so every
  run, however short, has a learning curve that ends at its final model.

SB3 is imported inside the factories, so importing this module needs no [rl] extra.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, TextIO

import numpy as np


def robot_object_impacts(robots: frozenset[str], objects: frozenset[str]) -> Callable[[dict], int]:
    """Counts the impacts in one step's ``info`` between a robot and an object (not walls, not each other)."""
    def count(info: dict) -> int:
        return sum(1 for i in info.get("impacts", ()) if {i["a"], i["b"]} & robots and {i["a"], i["b"]} & objects)

    return count


def _clock(seconds: float) -> str:
    seconds = int(max(seconds, 0))
    return f"{seconds // 3600}:{seconds // 60 % 60:02d}:{seconds % 60:02d}"


def progress_callback(total_steps: int, interactive: bool | None = None, period_s: float = 30.0,
                      stream: TextIO | None = None):
    """A bar on a terminal, plain lines otherwise (``interactive`` None: whether ``stream`` is a terminal)."""
    from stable_baselines3.common.callbacks import BaseCallback

    stream = stream or sys.stdout
    interactive = stream.isatty() if interactive is None else interactive

    class Progress(BaseCallback):
        def _on_training_start(self) -> None:
            self._start = time.perf_counter()
            self._first = self.model.num_timesteps
            self._last_line = -float("inf")
            self._bar = None
            if interactive:
                from tqdm import tqdm

                self._bar = tqdm(total=total_steps, initial=self._first, unit="step", file=stream,
                                 dynamic_ncols=True, smoothing=0.05)

        def _on_step(self) -> bool:
            if self._bar is not None:
                self._bar.n = min(self.model.num_timesteps, total_steps)
                self._bar.refresh() if self.n_calls % 64 == 0 else None
            return True

        def _on_rollout_end(self) -> None:
            if self._bar is None and time.perf_counter() - self._last_line >= period_s:
                self.line()

        def line(self) -> None:
            self._last_line = now = time.perf_counter()
            done = self.model.num_timesteps
            elapsed = now - self._start
            rate = (done - self._first) / elapsed if elapsed > 0 else 0.0
            eta = (total_steps - done) / rate if rate > 0 else float("nan")
            print(f"  step {done:,}/{total_steps:,} ({100 * done / total_steps:.0f}%)  {rate:,.0f} steps/s  "
                  f"elapsed {_clock(elapsed)}  eta {_clock(eta) if np.isfinite(eta) else '?'}", file=stream,
                  flush=True)

        def _on_training_end(self) -> None:
            if self._bar is not None:
                self._bar.n = min(self.model.num_timesteps, total_steps)
                self._bar.close()
            else:
                self.line()

    return Progress()


def task_metrics_callback(count_impacts: Callable[[dict], int], prefix: str = "rollout"):
    """Logs the task's robustness, success, fuel and robot-object impacts of finished training episodes."""
    from stable_baselines3.common.callbacks import BaseCallback

    class TaskMetrics(BaseCallback):
        def _on_training_start(self) -> None:
            self._impacts = np.zeros(self.training_env.num_envs, dtype=int)

        def _on_step(self) -> bool:
            infos, dones = self.locals.get("infos", ()), self.locals.get("dones", ())
            for k, (info, done) in enumerate(zip(infos, dones)):
                self._impacts[k] += count_impacts(info)
                if done and "robustness" in info:
                    record_episode(self.logger, prefix, info, int(self._impacts[k]))
                    self._impacts[k] = 0
            return True

    return TaskMetrics()


def record_episode(logger: Any, prefix: str, info: dict, impacts: int) -> None:
    logger.record_mean(f"{prefix}/robustness", float(info["robustness"]))
    logger.record_mean(f"{prefix}/fuel_Ns", float(info.get("fuel_Ns", 0.0)))
    logger.record_mean(f"{prefix}/impacts", float(impacts))
    if prefix != "eval":  # EvalCallback logs eval/success_rate itself
        logger.record_mean(f"{prefix}/success_rate", float(bool(info.get("is_success"))))


def evaluation_callback(eval_env: Any, count_impacts: Callable[[dict], int], previous: Path | None = None,
                        **kwargs: Any):
    """``EvalCallback(eval_env, **kwargs)`` with the task's metrics, resumed evaluations and a final evaluation.

    ``previous``: an ``evaluations.npz`` of the run being resumed; its evaluations are kept in front of the new.
    """
    from stable_baselines3.common.callbacks import EvalCallback

    class TaskEval(EvalCallback):
        def _init_callback(self) -> None:
            super()._init_callback()
            self._impacts = np.zeros(self.eval_env.num_envs, dtype=int)
            if previous is not None and previous.is_file():
                with np.load(previous, allow_pickle=False) as data:
                    self.evaluations_timesteps = [int(t) for t in data["timesteps"]]
                    self.evaluations_results = [list(r) for r in data["results"]]
                    self.evaluations_length = [list(n) for n in data["ep_lengths"]]
                    if "successes" in data:
                        self.evaluations_successes = [list(s) for s in data["successes"]]

        def _log_success_callback(self, locals_: dict[str, Any], globals_: dict[str, Any]) -> None:
            super()._log_success_callback(locals_, globals_)
            info, i = locals_["info"], locals_["i"]
            self._impacts[i] += count_impacts(info)
            if locals_["done"]:
                record_episode(self.logger, "eval", info, int(self._impacts[i]))
                self._impacts[i] = 0

        def _on_training_end(self) -> None:
            if not self.evaluations_timesteps or self.evaluations_timesteps[-1] < self.num_timesteps:
                saved, self.eval_freq = self.eval_freq, 1  # evaluate now, whatever the step count
                try:
                    self._on_step()
                finally:
                    self.eval_freq = saved

    return TaskEval(eval_env, **kwargs)


def wall_clock_budget(seconds: float):
    """A callback that ends training once ``seconds`` of wall clock have passed (a compute budget)."""
    from stable_baselines3.common.callbacks import BaseCallback

    class WallClockBudget(BaseCallback):
        def _on_training_start(self) -> None:
            self._deadline = time.perf_counter() + seconds

        def _on_step(self) -> bool:
            return time.perf_counter() < self._deadline

    return WallClockBudget()
