"""The expert controller (offline plan + online replanner + MPC, and what goes beyond the paper) and its named
stacks.

- :mod:`~planners.expert.expert`: :class:`Expert`, :class:`ExpertConfig`, and :func:`make_expert`, the
  ``impact_env.controllers`` entry point (``impact-env run SCENARIO --controller expert``);
- :mod:`~planners.expert.stacks`: the named stacks ``paper``, ``+id``, ``+mission`` and ``all``;
- :mod:`~planners.expert.wrappers`: a Gymnasium wrapper that labels observations with the expert's action
  (imported on use: it loads gymnasium's wrappers).
"""

from planners.expert.expert import Expert, ExpertConfig, ExpertStats, make_expert
from planners.expert.stacks import STACKS, stack_config

__all__ = ["STACKS", "Expert", "ExpertConfig", "ExpertStats", "make_expert", "stack_config"]
