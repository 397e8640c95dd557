"""Typed errors of the planners (all :class:`impact_env.errors.ImpactEnvError`; see that module's contract)."""

from __future__ import annotations

from typing import Any

from impact_env.errors import ImpactEnvError


class PlannerError(ImpactEnvError):
    """Base class of planner errors."""


class UnsupportedSpecError(PlannerError, ValueError):
    """The task uses an STL construct the MILP planner cannot encode (e.g. nested temporal operators)."""


class SolverNotAvailableError(PlannerError, ImportError):
    """The requested solver backend is not installed; the message says which extra installs it."""


class InfeasiblePlanError(PlannerError):
    """No plan satisfies the task; ``groups`` names the constraint groups that conflict."""

    def __init__(self, message: str, groups: list[str] | None = None) -> None:
        super().__init__(message)
        self.groups = list(groups or [])


class UnflyableHandoverError(InfeasiblePlanError):
    """A plan asks a robot to get round an object between two of its impacts (:mod:`planners.plan.handover`)
    or on its way to its first impact (:mod:`planners.plan.approach`) in less time than that takes, and the
    planner could not repair it. ``handovers`` are the hand-overs and approaches (robot, object, times, least
    time needed, time there is); ``plan`` the plan that has them, or None when no plan without them satisfies
    the task."""

    def __init__(self, message: str, handovers: list[Any] | None = None, plan: Any = None,
                 groups: list[str] | None = None) -> None:
        super().__init__(message, groups=groups)
        self.handovers = list(handovers or [])
        self.plan = plan


class PlanTimeoutError(PlannerError):
    """The solver hit its time limit, or its node budget before it found any plan. ``plan`` is the best plan found
    (or None) and ``mip_gap`` its gap."""

    def __init__(self, message: str, plan: Any = None, mip_gap: float | None = None) -> None:
        super().__init__(message)
        self.plan = plan
        self.mip_gap = mip_gap


class MPCInputError(PlannerError, ValueError):
    """A configuration value or a solve() input of the MPC has the wrong shape, range or is not finite."""


class ReplanInputError(PlannerError, ValueError):
    """An online replanner input out of range: a segment's times out of order, its duration, degree or bounds."""


class PlanCheckError(PlannerError, ValueError):
    """A plan violates continuity, bounds, thrust limits or the impact law; lists every violation."""

    def __init__(self, violations: list[str], source: str | None = None) -> None:
        where = f" for {source}" if source else ""
        super().__init__(f"plan check failed{where}:\n  " + "\n  ".join(violations))
        self.violations = violations
        self.source = source


# ------------------------------------------------------------------------------------ tether planners


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


class SmtNoPlanError(PlannerError):
    """The thesis's SMT pipeline found no plan within its bounds (not a proof that none exists)."""

    def __init__(self, message: str, stats: dict | None = None) -> None:
        super().__init__(message)
        self.stats = dict(stats or {})


PLANNER_ERRORS: tuple[type[ImpactEnvError], ...] = (
    PlannerError, UnsupportedSpecError, SolverNotAvailableError, InfeasiblePlanError, UnflyableHandoverError,
    PlanTimeoutError, MPCInputError, ReplanInputError, PlanCheckError, DecompositionError, TetherInfeasibleError,
    TetherPlanCheckError, SmtNoPlanError,
)

