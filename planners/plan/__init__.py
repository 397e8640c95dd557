"""The Plan noun: what the offline planners write, the expert follows and the plotter draws.

- :mod:`~planners.plan.types`: its parts (segments, body plans, impacts, funnels, copies);
- :mod:`~planners.plan.plan`: the :class:`Plan` itself (queries, JSON, ``check``);
- :mod:`~planners.plan.funnels`: the maths of an impact-robust plan's funnels and copies;
- :mod:`~planners.plan.checks`: what ``Plan.check`` verifies;
- :mod:`~planners.plan.schema` and :mod:`~planners.plan.files`: the plan file, field by field and on disk;
- :mod:`~planners.plan.plotting`: the figures (imported on use: it loads matplotlib).

Imports run one way, types <- funnels <- checks <- plan, so the package has no import circle.
"""

from planners.plan.checks import PLAN_CHECKS
from planners.plan.plan import Plan
from planners.plan.types import BodyPlan, ImpactCopies, ObjectFunnel, PlannedImpact, Segment

__all__ = ["PLAN_CHECKS", "BodyPlan", "ImpactCopies", "ObjectFunnel", "Plan", "PlannedImpact", "Segment"]
