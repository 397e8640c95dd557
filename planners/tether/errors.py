"""Typed errors of the tether planners."""

from __future__ import annotations

from planners.errors import InfeasiblePlanError, PlanCheckError, PlannerError


class DecompositionError(PlannerError, ValueError):
    """A polygon the convex decomposition cannot take (not simple, too few vertices), or pieces that fail to
    tile it (a bug: the message lists the area that is missing or doubled)."""


class TetherInfeasibleError(InfeasiblePlanError):
    """No anchor sequence carries the cargo into the goal box.

    ``certificate`` is the proof: the backward-reachable set reached a fixed point (a level added nothing) and
    does not contain the start; it holds the number of levels, the reachable area (m^2) and the start's
    distance (m) to the reachable set.
    """

    def __init__(self, message: str, certificate: dict | None = None, groups: list[str] | None = None) -> None:
        super().__init__(message, groups=groups)
        self.certificate = dict(certificate or {})


class TetherPlanCheckError(PlanCheckError):
    """A tether plan leaves the free space, loses line of sight, or does not end in the goal box."""


__all__ = ["DecompositionError", "PlannerError", "TetherInfeasibleError", "TetherPlanCheckError"]
