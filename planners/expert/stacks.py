"""The expert's named stacks: the paper's controller and what each part beyond it adds.

The robustness benchmark (``benchmarks/robustness.py``) and the docs compare these four; each is an
:class:`~planners.expert.ExpertConfig`:

- ``paper``: the paper's stack, local replanning at planned impacts only (:meth:`ExpertConfig.paper`);
- ``+id``: the paper's stack with online identification of restitution;
- ``+mission``: the paper's stack with mission-level replanning;
- ``all``: every part (``ExpertConfig()``).
"""

from __future__ import annotations

import dataclasses

from planners.errors import PlannerError
from planners.expert.expert import ExpertConfig
from planners.online.identification import IdentificationConfig
from planners.online.mission import MissionConfig

STACKS = ("paper", "+id", "+mission", "all")


def stack_config(name: str, allow_side_switches: bool = False) -> ExpertConfig:
    """The ``ExpertConfig`` of stack ``name`` (one of :data:`STACKS`). ``allow_side_switches`` flies mission
    re-plans that have a side switch, as the benchmark's cells flown before
    ``MissionConfig.allow_side_switches`` existed were."""
    if name not in STACKS:
        raise PlannerError(f"unknown expert stack {name!r}: one of {', '.join(STACKS)}")
    config = {"paper": ExpertConfig.paper(), "+id": ExpertConfig.paper(identification=IdentificationConfig()),
              "+mission": ExpertConfig.paper(mission=MissionConfig()), "all": ExpertConfig()}[name]
    if allow_side_switches and config.mission is not None:
        config = dataclasses.replace(config, mission=dataclasses.replace(config.mission, allow_side_switches=True))
    return config
