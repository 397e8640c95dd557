"""Controllers that fly the Gymnasium environment, and a registry for those defined elsewhere.

A controller maps the central observation to an action of the Gymnasium env. Built-in: ``zero`` (no
thrust) and ``random`` (uniform in the action box, seeded). Other packages add controllers through the
``impact_env.controllers`` entry-point group (e.g. the expert in ``planners/``): this keeps the data flow
one-way, ``impact_env`` never imports ``planners`` or ``baselines``.
"""

from __future__ import annotations

from importlib.metadata import entry_points
from typing import Any, Protocol

import gymnasium as gym
import numpy as np

from impact_env.errors import ControllerError

ENTRY_POINT_GROUP = "impact_env.controllers"


class Controller(Protocol):
    """What ``impact-env run`` and the benchmarks drive: reset once per episode, then act per step."""

    name: str

    def reset(self, env: gym.Env, seed: int | None) -> None: ...

    def act(self, observation: np.ndarray, info: dict[str, Any]) -> np.ndarray: ...


class ZeroController:
    """No thrust at all: the baseline every task should fail with (objects never move)."""

    name = "zero"

    def reset(self, env: gym.Env, seed: int | None) -> None:
        self._shape = env.action_space.shape

    def act(self, observation: np.ndarray, info: dict[str, Any]) -> np.ndarray:
        return np.zeros(self._shape, dtype=np.float32)  # type: ignore[arg-type]  # a Box: its shape is set


class RandomController:
    """Uniform random actions from the action box, reproducible from the episode seed."""

    name = "random"

    def reset(self, env: gym.Env, seed: int | None) -> None:
        self._space = env.action_space
        self._space.seed(seed)

    def act(self, observation: np.ndarray, info: dict[str, Any]) -> np.ndarray:
        return self._space.sample()


BUILTIN: dict[str, type[Controller]] = {"zero": ZeroController, "random": RandomController}


def available_controllers() -> list[str]:
    """Built-in names and those registered through the entry-point group."""
    return sorted(set(BUILTIN) | {ep.name for ep in entry_points(group=ENTRY_POINT_GROUP)})


def make_controller(spec: str, scenario: Any, **options: Any) -> Controller:
    """Build a controller from its name (``zero``, ``random`` or a registered one), a ``model.zip`` path, or
    ``name:ARGUMENT`` for a registered controller that loads something (``rllib:runs/ppo_x``: ARGUMENT is
    passed as ``model=``).

    Registered factories are called as ``factory(scenario, **options)``; options that are None are left
    out (e.g. ``plan=None`` when ``--plan`` was not given).
    """
    if spec in BUILTIN:
        return BUILTIN[spec]()  # they take no options
    if spec.endswith(".zip"):  # a saved stable-baselines3 model: the "sb3" controller of baselines/
        spec, options = "sb3", {**options, "model": spec}
    elif ":" in spec and spec.partition(":")[0] in {ep.name for ep in entry_points(group=ENTRY_POINT_GROUP)}:
        spec, model = spec.split(":", 1)
        options = {**options, "model": model}
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        if ep.name == spec:
            return ep.load()(scenario, **{k: v for k, v in options.items() if v is not None})
    from pathlib import Path

    from impact_env.catalogue import suggestion

    if (Path(spec) / "model.zip").is_file():
        raise ControllerError(f"{spec!r} is a run folder, not a controller: give its model, --controller "
                              f"{Path(spec) / 'model.zip'}")
    raise ControllerError(f"unknown controller {spec!r}{suggestion(spec, available_controllers())}; available: "
                          f"{', '.join(available_controllers())}, or a model path ending in .zip")
