"""Typed errors of the tether planners (defined with every other planner error in :mod:`planners.errors`)."""

from __future__ import annotations

from planners.errors import (
    DecompositionError,
    PlannerError,
    SmtNoPlanError,
    TetherInfeasibleError,
    TetherPlanCheckError,
)

__all__ = ["DecompositionError", "PlannerError", "SmtNoPlanError", "TetherInfeasibleError", "TetherPlanCheckError"]
