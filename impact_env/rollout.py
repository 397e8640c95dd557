"""Run episodes of a controller in a Gymnasium env and summarise them (the CLI's ``run``, benchmarks)."""

from __future__ import annotations

import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np

from impact_env.controllers import Controller


@dataclass
class EpisodeResult:
    """Summary of one episode; ``positions`` is (steps + 1, n_bodies, 2) in metres."""

    seed: int | None
    success: bool
    robustness: float
    impacts: list[dict[str, Any]]
    fuel_Ns: float
    steps: int
    return_: float
    wall_time_s: float
    controller_ms: list[float] = field(default_factory=list)
    times_s: np.ndarray | None = None
    positions: np.ndarray | None = None
    frames: list[np.ndarray] | None = None
    extra: dict[str, Any] | None = None  # the controller's own report, if it has one
    final_info: dict[str, Any] = field(default_factory=dict)  # the environment's info after the last step

    def summary(self) -> dict[str, Any]:
        """JSON-ready dict (no arrays)."""
        ms = np.asarray(self.controller_ms) if self.controller_ms else np.zeros(1)
        return {
            "seed": self.seed, "success": bool(self.success), "robustness": float(self.robustness),
            "impacts": self.impacts, "fuel_Ns": float(self.fuel_Ns), "steps": self.steps,
            "return": float(self.return_), "wall_time_s": self.wall_time_s,
            "controller_ms": {"median": float(np.median(ms)), "p99": float(np.percentile(ms, 99))},
            **({"controller_report": self.extra} if self.extra else {}),
        }


def robot_object_impacts(scenario, impacts: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The impacts (dicts with ``a`` and ``b``) between a robot and an object, not with walls or each other."""
    robots, objects = {r.name for r in scenario.robots}, {o.name for o in scenario.objects}
    return [i for i in impacts if {i["a"], i["b"]} & robots and {i["a"], i["b"]} & objects]


def run_episode(env: gym.Env, controller: Controller, seed: int | None = None,
                record_frames: bool = False) -> EpisodeResult:
    """Reset with ``seed``, let the controller act until the episode ends, return its summary.

    ``env`` is a :class:`~impact_env.transport.gym_env.TransportEnv` or a
    :class:`~impact_env.tether.gym_env.TetherEnv` (possibly wrapped): a tether env's one body is the cargo, and
    it reports no impacts and no fuel.
    """
    start = time.perf_counter()
    obs, info = env.reset(seed=seed)
    controller.reset(env, seed)
    core = env.unwrapped.core  # type: ignore[attr-defined]  # a TransportEnv or a TetherEnv: both have one
    positions = [[s[:2] for s in core._state]]
    frames: list[Any] | None = [env.render()] if record_frames else None
    ms: list[float] = []
    total = 0.0
    impacts: list[dict[str, Any]] = []
    done = False
    while not done:
        t0 = time.perf_counter()
        action = controller.act(obs, info)
        ms.append(1e3 * (time.perf_counter() - t0))
        obs, reward, terminated, truncated, info = env.step(action)
        total += reward  # type: ignore[operator]  # gymnasium says SupportsFloat; both envs return a float
        impacts.extend(info.get("impacts", ()))  # the tether environments have no impacts
        positions.append([s[:2] for s in core._state])
        if frames is not None:  # record_frames
            frames.append(env.render())
        done = terminated or truncated
    steps = len(positions) - 1
    return EpisodeResult(
        seed=seed, success=bool(info["is_success"]), robustness=float(info["robustness"]), impacts=impacts,
        fuel_Ns=float(info.get("fuel_Ns", 0.0)), steps=steps, return_=total, wall_time_s=time.perf_counter() - start,
        controller_ms=ms, times_s=np.arange(steps + 1) * core.dt_s, positions=np.array(positions), frames=frames,
        final_info=info,
    )


def run_episodes(env: gym.Env, controller: Controller, first_seed: int, episodes: int,
                 record_first: bool = False) -> Iterator[EpisodeResult]:
    """:func:`run_episode` with seeds ``first_seed, first_seed + 1, ...``, each result as its episode ends.

    A controller with a ``report()`` (e.g. the expert's planned-versus-executed numbers) has it stored in the
    result's ``extra``; ``record_first`` keeps the first episode's frames.
    """
    for k in range(episodes):
        result = run_episode(env, controller, seed=first_seed + k, record_frames=record_first and k == 0)
        if hasattr(controller, "report"):
            result.extra = controller.report()
        yield result


def statistics(results: list[EpisodeResult]) -> dict[str, float]:
    """Success rate and robustness mean and standard deviation (m) over episodes: the CLI summary's numbers."""
    return {
        "success_rate": float(np.mean([r.success for r in results])),
        "robustness_mean": float(np.mean([r.robustness for r in results])),
        "robustness_std": float(np.std([r.robustness for r in results])),
    }


def write_video(frames: list[np.ndarray], path: str, fps: int) -> None:
    """Write RGB frames (H, W, 3) uint8 to an mp4 (H.264 through the ffmpeg that imageio-ffmpeg ships),
    atomically (:func:`impact_env.results_store.atomic_path`)."""
    import imageio_ffmpeg

    if not frames:
        raise ValueError("no frames to write")
    from impact_env.results_store import atomic_path

    h, w = frames[0].shape[:2]
    pad = ((0, h % 2), (0, w % 2), (0, 0))  # H.264 in yuv420p needs even sizes
    h, w = h + h % 2, w + w % 2
    with atomic_path(path) as tmp:  # the temporary file keeps the suffix, from which ffmpeg picks the container
        writer = imageio_ffmpeg.write_frames(str(tmp), (w, h), fps=fps, macro_block_size=1, quality=7,
                                             ffmpeg_log_level="error")
        writer.send(None)
        for frame in frames:
            writer.send(np.ascontiguousarray(np.pad(frame, pad, mode="edge") if any(p[1] for p in pad) else frame))
        writer.close()
