"""BenchMARL's task class for the batched impact world: MAPPO, IPPO and every other BenchMARL algorithm train
on :class:`~impact_env.transport.batched.torchrl_env.TransportTorchRLEnv` unchanged.

    from benchmarl.algorithms import MappoConfig
    from benchmarl.experiment import Experiment, ExperimentConfig
    from benchmarl.models import MlpConfig
    from baselines.batched.benchmarl_task import ImpactTask

    task = ImpactTask.CORRIDOR.get_task(config={"thrust_noise": 0.05})   # or ImpactTaskClass("my.toml", {...})
    Experiment(task, MappoConfig.get_from_yaml(), MlpConfig.get_from_yaml(), MlpConfig.get_from_yaml(),
               seed=0, config=ExperimentConfig.get_from_yaml()).run()

The task's config holds the world's options (``reward_mode``, ``thrust_noise``, ``initial_position_noise_m``,
``restitution``, ``fuel_penalty``, ``impact_velocity_noise_mps``, ``dtype`` as ``"float32"``/``"float64"``)
and ``compile_min_envs``: batches of at least that many envs run through torch.compile (the training batch),
smaller ones eagerly (BenchMARL's evaluation batch, which would otherwise cost a compilation of its own).
An unknown key is an error. The group is ``agents`` (one per robot), ``state`` feeds MAPPO's central critic,
and evaluation episodes last the task's horizon.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import torch
from benchmarl.environments.common import Task, TaskClass
from torchrl.data import Composite
from torchrl.envs import EnvBase

from impact_env.errors import EnvConfigError

WORLD_OPTIONS = ("reward_mode", "fuel_penalty", "restitution", "thrust_noise", "initial_position_noise_m",
                 "impact_velocity_noise_mps")
DEFAULTS: dict[str, Any] = {"dtype": "float32", "compile_min_envs": 256}


class ImpactTaskClass(TaskClass):
    """A BenchMARL task of one scenario: ``name`` is a shipped scenario name or a path to a TOML file."""

    def __init__(self, name: str, config: dict[str, Any] | None) -> None:
        config = {**DEFAULTS, **(config or {})}
        unknown = sorted(set(config) - set(WORLD_OPTIONS) - set(DEFAULTS))
        if unknown:
            raise EnvConfigError(f"ImpactTaskClass has no option {', '.join(map(repr, unknown))}; its options are "
                                 f"{', '.join((*WORLD_OPTIONS, *DEFAULTS))}")
        if config["dtype"] not in ("float32", "float64"):
            raise EnvConfigError(f"dtype must be 'float32' or 'float64', got {config['dtype']!r}")
        super().__init__(name=name, config=config)
        self._horizon: int | None = None

    @property
    def scenario(self) -> str:
        """The scenario the envs run: the enum member's name in lower case, or the path given."""
        return self.name.lower() if self.name.isupper() else self.name

    def get_env_fun(self, num_envs: int, continuous_actions: bool, seed: int | None,
                    device: Any) -> Callable[[], EnvBase]:
        from impact_env.transport.batched.torchrl_env import TransportTorchRLEnv

        options = {k: v for k, v in self.config.items() if k in WORLD_OPTIONS}
        dtype = getattr(torch, self.config["dtype"])
        compile_ = num_envs >= self.config["compile_min_envs"]
        scenario = self.scenario

        def make() -> EnvBase:
            env = TransportTorchRLEnv(scenario, num_envs, device=device, dtype=dtype, compile=compile_, **options)
            if seed is not None:
                env.set_seed(seed)
            return env

        return make

    def supports_continuous_actions(self) -> bool:
        return True

    def supports_discrete_actions(self) -> bool:
        return False

    def has_render(self, env: EnvBase) -> bool:
        return False

    def max_steps(self, env: EnvBase) -> int:
        return env.world.horizon_steps

    def group_map(self, env: EnvBase) -> dict[str, list[str]]:
        return env.group_map

    def observation_spec(self, env: EnvBase) -> Composite:
        spec = env.full_observation_spec_unbatched.clone()
        del spec["state"]
        for group in self.group_map(env):
            del spec[(group, "info")]
        return spec

    def info_spec(self, env: EnvBase) -> Composite | None:
        spec = env.full_observation_spec_unbatched.clone()
        del spec["state"]
        for group in self.group_map(env):
            del spec[(group, "observation")]
        return spec

    def state_spec(self, env: EnvBase) -> Composite | None:
        return Composite({"state": env.full_observation_spec_unbatched["state"].clone()})

    def action_spec(self, env: EnvBase) -> Composite:
        return env.full_action_spec_unbatched

    def action_mask_spec(self, env: EnvBase) -> Composite | None:
        return None

    @staticmethod
    def env_name() -> str:
        return "impact_env"


class ImpactTask(Task):
    """The shipped scenarios as BenchMARL tasks (``ImpactTask.CORRIDOR.get_task(config={...})``); any other
    scenario file is ``ImpactTaskClass(path, config)``."""

    CORRIDOR = None
    LONG_THROW_TRIM = None
    OBSTACLE_AVOIDANCE = None
    PING_PONG_STOP = None
    RELAY = None
    THROW_AND_CATCH_EXP = None
    TWO_OBJECTS = None

    @staticmethod
    def associated_class() -> type[ImpactTaskClass]:
        return ImpactTaskClass

    def get_task(self, config: dict[str, Any] | None = None) -> ImpactTaskClass:
        """The task with ``config`` (default: :data:`DEFAULTS`; there is no YAML file to read)."""
        return ImpactTaskClass(name=self.name, config=config)
