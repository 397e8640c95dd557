"""What the spatially robust and the impact-robust planners build the same way: the time grid from the
config and the scenario's hints, the task's conjuncts (one constraint group each) and the obstacle
clearance, and the checks of the options they share."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from impact_env.transport.scenario import Scenario
from planners.errors import PlannerError
from planners.offline.config import PlannerConfig
from planners.offline.milp.model import LinExpr, Model
from planners.offline.milp.stl_encoding import STLEncoder
from planners.offline.milp.trajectories import Grid

DEFAULT_INTERVALS = 10
DEFAULT_DEGREE = 4


def check_common_options(scenario: Scenario, config: PlannerConfig) -> tuple[Grid, int]:
    """The time grid and the robots' curve degree from the options (their own checks are the config's) and the
    scenario's hints; PlannerError if the scenario has no object or the hints make too small a grid."""
    if not scenario.objects:
        raise PlannerError(f"scenario {scenario.name!r} has no object to transport")
    n = config.intervals or scenario.planner_intervals or DEFAULT_INTERVALS
    degree = config.robot_degree or scenario.planner_robot_degree or DEFAULT_DEGREE
    if n < 2 or degree < 2:
        raise PlannerError(f"need at least 2 intervals and robot degree >= 2, got {n} and {degree}")
    return Grid(n, scenario.tf_s), degree


def add_obstacle_clearance(encoder: STLEncoder, scenario: Scenario, n: int) -> None:
    """Every body's whole curve (all its points) at least its radius outside every solid obstacle."""
    for body in scenario.bodies:
        for obstacle in scenario.obstacles:
            for k in range(n):
                encoder.clearance(body.name, obstacle.name, k, body.radius_m, group="obstacle clearance")


@dataclass
class EncodedTask:
    """The task's top-level conjuncts, their robustness expressions and their constraint groups."""

    conjuncts: tuple
    robustness: list[LinExpr]
    groups: list[str]
    rho: LinExpr | None = None


def encode_task(model: Model, encoder: STLEncoder, scenario: Scenario,
                rho: LinExpr | Callable[[list[LinExpr]], LinExpr] | None = None,
                min_robustness_m: float = 0.0) -> EncodedTask:
    """Encode each top-level conjunct of the task in its own group and require it satisfied (r_c >=
    ``min_robustness_m``, ``PlannerConfig.min_robustness_m``); with ``rho``, also rho <= r_c for every conjunct
    (group "robustness objective").

    Satisfaction lives in the conjuncts' own groups, not in a bound, so that an infeasible task is explained
    by the conjuncts that cause it. ``rho`` may be a callable ``rho(encoded) -> LinExpr`` creating the
    variable once the conjuncts' bounds are known.
    """
    formula = scenario.formula
    conjuncts = formula.children if type(formula).__name__ == "And" else (formula,)
    encoded, groups = [], []
    for c in conjuncts:
        groups.append(f"task: {c}")
        encoder.group = groups[-1]  # a conjunct's encoding rows live in its own group
        encoded.append(encoder.encode(c))
    if callable(rho):
        rho = rho(encoded)
    for group, r_c in zip(groups, encoded):
        model.add(r_c >= min_robustness_m, group=group)
        if rho is not None:
            model.add(rho <= r_c, group="robustness objective")
    return EncodedTask(tuple(conjuncts), encoded, groups, rho)
