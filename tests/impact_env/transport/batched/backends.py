"""The pymunk world and the batched world behind one small interface, for tests that run against both.

torch and the batched package are imported when a batched backend is made, not when a test module that
names the backends is collected."""

from __future__ import annotations

import numpy as np

from impact_env.transport.physics import World
from impact_env.transport.scenario import Scenario

BACKENDS = ("pymunk", "batched")


class PymunkBackend:
    """One pymunk World stepped with zero thrust."""

    def __init__(self, scenario: Scenario) -> None:
        self.world = World(scenario)
        self.n_robots = len(scenario.robots)
        self.dt_s = scenario.control_period_s

    def step(self) -> int:
        """One control period without thrust; returns the number of contacts that ended in it."""
        return len(self.world.step([(0.0, 0.0, 0.0)] * self.n_robots))

    def state(self) -> np.ndarray:
        """[B, 6]: x, y, vx, vy, heading, yaw rate."""
        return np.array(self.world.read_state())

    def touching(self) -> bool:
        return bool(self.world._open)


class BatchedBackend:
    """One env of a float64 BatchedTransportWorld stepped with zero actions."""

    def __init__(self, scenario: Scenario) -> None:
        import torch

        from impact_env.transport.batched import BatchedTransportWorld

        self.world = BatchedTransportWorld(scenario, 1, dtype=torch.float64)
        self.world.reset(seeds=0)
        self.dt_s = scenario.control_period_s

    def step(self) -> int:
        import torch

        _, _, _, _, info = self.world.step(torch.zeros(1, self.world.action_size, dtype=torch.float64))
        return int(info["impacts"][0])

    def state(self) -> np.ndarray:
        return self.world.body_state()[0].numpy()

    def touching(self) -> bool:
        lay = self.world.layout
        return bool((self.world.rows[lay.pair_on.start:lay.static_on.stop, 0] > 0.5).any())


def make_backend(name: str, scenario: Scenario) -> PymunkBackend | BatchedBackend:
    return PymunkBackend(scenario) if name == "pymunk" else BatchedBackend(scenario)


def shipped_scenarios(fast: tuple[str, ...]) -> list:
    """Every shipped scenario as a parameter; those outside ``fast`` run in the slow suite only (the default
    suite keeps a representative few, so that its share of the batched tests stays small)."""
    import pytest

    from impact_env.transport.scenario import scenario_names

    unknown = set(fast) - set(scenario_names())
    assert not unknown, f"not shipped: {sorted(unknown)}"
    return [name if name in fast else pytest.param(name, marks=pytest.mark.slow) for name in scenario_names()]
