"""Options of the offline planners: :class:`PlannerConfig` (spatially robust) and :class:`IRPlannerConfig`
(impact-robust, which extends it), with the solver budget nested as one :class:`SolverOptions`.

They live apart from the planners because the lexicographic stages (:mod:`planners.offline.stages`), which
both planners call, read them too. The solve is lexicographic: (1) maximise the primary quantity (rho or
delta); (2) keeping it, minimise the number of impacts plus the L1 acceleration (Eq. 28), cut after
``refine_nodes`` branch-and-bound nodes; (3) with the binaries fixed, an LP with the stage-2 objective, or
with ``smooth`` the QP on squared accelerations. Why stage 2 is cut by nodes and not by time:
``docs/planner_design.md#lexicographic-stages``.
"""

from __future__ import annotations

from dataclasses import KW_ONLY, InitVar, dataclass, field
from typing import Any

from impact_env.config_checks import (
    NOT_GIVEN,
    check_choice,
    check_flag,
    check_instance,
    check_integer,
    check_number,
    fail,
    is_finite_number,
    moved_into,
)
from planners.errors import PlannerError
from planners.offline.solvers import SOLVERS
from planners.offline.solvers.base import SolverOptions
from planners.plan import Plan

__all__ = ["DEFAULT_COPY_INTERVALS", "DEFAULT_FINAL_BOX", "DEFAULT_NODE_BUDGET", "DEFAULT_SAFETY_NET_S",
           "DEFAULT_THREADS", "HandoverConfig", "IRPlannerConfig", "PlannerConfig", "SolverOptions"]

DEFAULT_FINAL_BOX = (0.5, 0.05)  # position half-width (m), velocity half-width (m/s): the authors' default
DEFAULT_COPY_INTERVALS = 2
# Stage 1's default budget is work, not time (docs/planner_design.md#the-budget): branch-and-bound nodes, with a
# wall-clock limit far beyond what the node budget takes on a busy machine, only as a safety net
DEFAULT_NODE_BUDGET = 20_000
DEFAULT_SAFETY_NET_S = 600.0
# HiGHS's tree depends on its thread count, and left to choose it takes the machine's cores: pinned, the default
# plan is the same on every machine (2: what the committed plans were made with on a 2-core machine)
DEFAULT_THREADS = 2
_SOLVER_KEYWORDS = ("time_limit_s", "node_limit", "mip_gap", "threads", "verbose", "seed", "progress")


def _planner_budget() -> SolverOptions:
    return SolverOptions(time_limit_s=DEFAULT_SAFETY_NET_S, node_limit=DEFAULT_NODE_BUDGET, threads=DEFAULT_THREADS)


# the impact-robust planner's stage-1 budget: six times the most a shipped scenario needs (obstacle_avoidance,
# 1,615 nodes on two threads; docs/planner_design.md#the-impact-robust-budget)
DEFAULT_IR_NODE_BUDGET = 10_000


def _ir_budget() -> SolverOptions:
    return SolverOptions(time_limit_s=DEFAULT_SAFETY_NET_S, node_limit=DEFAULT_IR_NODE_BUDGET, threads=DEFAULT_THREADS)


@dataclass(frozen=True)
class HandoverConfig:
    """How the offline planners make sure that a robot hitting one object twice in a row from opposite sides
    has time to get round it in between (:mod:`planners.plan.handover`), and that a robot whose way to its
    first impact is blocked by the object has time to get round it (:mod:`planners.plan.approach`; why the
    numbers: ``docs/planner_design.md#hand-overs``). A plan with too little time is repaired: the planner
    re-solves without that hand-over (the same robot and object at the same two knots, nothing hitting either
    in between) or that first impact, up to ``repairs`` times in all, and records what it cut in
    ``plan.stats["handovers_cut"]`` and ``["approaches_cut"]``."""

    margin: float = 0.5
    """The time between the two impacts (or up to the first) must be at least (1 + margin) times the least time
    getting round takes at the robot's thrust limit (a fraction): that least time is a lower bound, and the
    online layer does not fly a time-optimal way round."""
    start_approach_margin: float | None = None
    """The margin of an approach from the robot's start state (nothing hits its object before): None, ``margin``.
    The mission layer's re-plans and trims, whose start is the observed state, set the margin it tests a way
    round from an observed state with (``MissionConfig.observed_handover_margin``, 0.25): nothing is left to
    predict there but the way round, and the mission's own test of that way would otherwise be overruled by a
    stricter one (timed_visits seed 3 at 0.02 m/s: the trim round O1, 1.39 times its least time, refused by
    the planner at 0.5 and the goal lost). Offline, 0.5 stays: the corridor's IR plan at 1.49 times lost 29 of
    50 episodes flown by the paper's stack, which has no mission layer to fly the way round."""
    later_approaches: bool = False
    """Also test (and repair) each later impact of a robot whose previous impact was on another object, when its
    way there must get round the object (:func:`planners.plan.approach.approaches` with ``later``; one robot
    serving two objects). False: first impacts only, as the committed plans were made; the mission layer's
    re-plans set it from ``MissionConfig.later_approaches``."""
    repairs: int = 20
    """Re-solves with the unflyable hand-overs cut out before the planner gives up with
    ``UnflyableHandoverError``; 0 refuses such a plan at once. Each cut excludes one pair of knots, so a task
    that a robot can only do with a hand-over may take several (the one-robot push and stop of
    ``docs/planner_design.md#hand-overs`` takes 14)."""

    def __post_init__(self) -> None:
        check_number(self, "margin", PlannerError, low=0)
        if self.start_approach_margin is not None:
            check_number(self, "start_approach_margin", PlannerError, low=0)
        check_integer(self, "repairs", PlannerError, low=0)
        check_flag(self, "later_approaches", PlannerError)

    def margin_of(self, check) -> float:
        """The margin a hand-over or approach (:class:`planners.plan.approach.Approach`) is tested with."""
        # an approach from the robot's start state (nothing hit its object before, and it hit nothing before)
        start = getattr(check, "by", False) is None and getattr(check, "after", None) is None
        return self.start_approach_margin if start and self.start_approach_margin is not None else self.margin


@dataclass(frozen=True)
class PlannerConfig:
    """Options of the spatially robust planner (see the module docstring for the stages).

    The solver budget's old keywords (``time_limit_s``, ``node_limit``, ``mip_gap``, ``threads``, ``verbose``,
    ``seed``, ``progress``) are still accepted for one release, with a ``DeprecationWarning``, and set in
    :attr:`solver_options`.
    """

    intervals: int | None = None
    """Intervals of the time grid; None: the scenario's ``[planner]`` hint, else 10."""
    robot_degree: int | None = None
    """Degree of the robots' Bezier curves; None: the scenario's ``[planner]`` hint, else 4."""
    thrust_fraction: float = 0.5
    """Share of each robot's thrust limit the plan may use (in (0, 1]); the rest is the controller's margin."""
    acceleration_weight: float = 1e-6
    """The L1 acceleration cost is scaled so that it can move rho by at most this much in stage 1 (m): a
    tie-break below the MIP gap."""
    impact_weight: float = 1e-6
    """The same for the number of impacts (m per impact)."""
    refine_nodes: int | None = 20
    """Branch-and-bound nodes of stage 2 (0 skips it; None: no limit)."""
    refine_time_s: float = DEFAULT_SAFETY_NET_S
    """Time limit of stage 2 (s): only a safety net, ``refine_nodes`` cuts it (0 skips it). It was 60 s before
    0.3.0, which a busy machine reached (``docs/planner_design.md#the-budget``)."""
    refine_warm_start: bool = True
    """Stage 2 starts from stage 1's incumbent (a MIP start); False: it starts cold, and the better of its
    incumbent and stage 1's is kept. Cold found the better stage-2 plan at the same 20-node cut on the three
    scenarios measured (four_robots: 4 impacts instead of 5; ``docs/planner_design.md#stage-2-what-the-node-cut-buys``);
    the default stays warm until the committed plans are re-planned and their cells re-flown."""
    smooth: bool = False
    """Stage 3 as the convex QP on squared accelerations (Eq. 28) instead of the LP: off by default, HiGHS's
    QP takes 1-30 s on these models, 10x the MILP."""
    obstacle_clearance: bool = True
    """Every body's whole curve at least its radius outside every solid obstacle."""
    robot_object_separation: bool = False
    """Keep robots' discs off objects' discs except on the intervals next to their impacts (off, as in the
    paper: conservative over whole intervals, it can make short tasks infeasible and costs ~10x solve time)."""
    solver: str = "highs"
    """The MILP backend: ``highs``, ``scip`` or ``gurobi``."""
    solver_options: SolverOptions = field(default_factory=_planner_budget)
    """Stage 1's solver budget (node limit, time limit, MIP gap, threads, seed, progress): by default
    ``DEFAULT_NODE_BUDGET`` (20,000) branch-and-bound nodes, the same work on any machine, on
    ``DEFAULT_THREADS`` (2) solver threads, since the search depends on the count, and a
    ``DEFAULT_SAFETY_NET_S`` (600 s) time limit that only a pathological model reaches. A stage 1 cut by its
    node limit returns its best plan with ``plan.mip_gap > 0`` and ``plan.stats["stage1_status"] ==
    "node_limit"``; one cut by the time limit raises ``PlanTimeoutError``. Its time limit also bounds stage 3,
    and stage 2 takes its threads, seed and log."""
    warm_start: Plan | None = field(default=None, compare=False)
    """A previous plan on the same grid to start from; None: a cold start."""
    diagnose_infeasibility: bool = True
    """On an infeasible task, name the conflicting constraint groups (re-solving once per group)."""
    bound_propagation: bool = True
    """Give every robustness variable its exact upper bound (off only to measure what it buys)."""
    min_robustness_m: float = 1e-4
    """The robustness every conjunct of the task must reach (m). STL satisfaction is strict (rho > 0): a task
    that can only reach rho = 0, such as ``F[0,100] in(O1, goal) & G[0,100] !in(O1, goal)``, is satisfied by no
    trajectory, yet a MILP held at r >= 0 finds "plans" at -1e-7 within its tolerances and cannot close its
    gap. With this margin such a task is infeasible, which the solver proves in seconds and the diagnosis
    explains. 0.1 mm lies far below any scenario's geometry and far above the solvers' tolerances (1e-7 .. 1e-6);
    0 is the constraint of 0.2 (the online replanner keeps it, :mod:`planners.online.mission`)."""
    handover: HandoverConfig | None = field(default_factory=HandoverConfig)
    """Refuse or repair a plan in which a robot has too little time to get round an object between two of its
    impacts (:class:`HandoverConfig`); None: not checked."""
    contact_cones: int | None = None
    """Room for the disc robot behind each contact (``planners/offline/milp/contact_room.py``): the robot's
    centre at an impact, a radius sum behind the object against the push, kept inside the world shrunk by its
    radius and out of solid obstacles, the circle of push directions cut into this many cones (>= 4). None: the
    robots are points that meet the object's centre (the paper's model; a push away from a wall can then ask
    the disc robot to stand beyond the wall). The impact-robust planner's default is 8; the spatially robust
    planner's stays None until the shipped plans are re-planned with it (``docs/generated_tasks.md``)."""
    conjunct_weight: float = 0.0
    """The own robustness of each top-level conjunct on an object, added to the maximised rho with this weight
    (the spatially robust planner): rho, the least of them, still leads, and among plans of (nearly) the same
    rho the one whose other objects keep more margin wins, instead of any plan that leaves them at rho (where
    the noise of a late impact has that margin to use). Conjuncts on robots alone (keep out of an obstacle)
    are left out: a robot is flown, not thrown. 0: rho alone (the paper's objective). A trade of rho for the
    others is accepted only at more than 1/weight to 1."""
    _: KW_ONLY
    time_limit_s: InitVar[Any] = NOT_GIVEN
    """Deprecated: ``solver_options.time_limit_s``."""
    node_limit: InitVar[Any] = NOT_GIVEN
    """Deprecated: ``solver_options.node_limit``."""
    mip_gap: InitVar[Any] = NOT_GIVEN
    """Deprecated: ``solver_options.mip_gap``."""
    threads: InitVar[Any] = NOT_GIVEN
    """Deprecated: ``solver_options.threads``."""
    verbose: InitVar[Any] = NOT_GIVEN
    """Deprecated: ``solver_options.verbose``."""
    seed: InitVar[Any] = NOT_GIVEN
    """Deprecated: ``solver_options.seed``."""
    progress: InitVar[Any] = NOT_GIVEN
    """Deprecated: ``solver_options.progress``."""

    def __post_init__(self, *solver_keywords: Any) -> None:
        check_instance(self, "solver_options", PlannerError, SolverOptions, what="a SolverOptions")
        moved_into(self, "solver_options", dict(zip(_SOLVER_KEYWORDS, solver_keywords)), PlannerError)
        check_integer(self, "intervals", PlannerError, low=2, none="the scenario's hint, else 10")
        check_integer(self, "robot_degree", PlannerError, low=2, none="the scenario's hint, else 4")
        check_number(self, "thrust_fraction", PlannerError, low=0, high=1, low_open=True)
        check_number(self, "acceleration_weight", PlannerError, low=0)
        check_number(self, "impact_weight", PlannerError, low=0)
        check_integer(self, "refine_nodes", PlannerError, low=0, none="no limit")
        check_number(self, "refine_time_s", PlannerError, low=0)
        check_number(self, "min_robustness_m", PlannerError, low=0, high=1)
        for name in ("refine_warm_start", "smooth", "obstacle_clearance", "robot_object_separation",
                     "diagnose_infeasibility", "bound_propagation"):
            check_flag(self, name, PlannerError)
        check_choice(self, "solver", PlannerError, SOLVERS)
        check_instance(self, "warm_start", PlannerError, Plan, what="a Plan", none="a cold start")
        check_instance(self, "handover", PlannerError, HandoverConfig, what="a HandoverConfig", none="not checked")
        check_integer(self, "contact_cones", PlannerError, low=4, none="point contacts (no room for the disc)")
        check_number(self, "conjunct_weight", PlannerError, low=0, high=1)


@dataclass(frozen=True)
class IRPlannerConfig(PlannerConfig):
    """Options of the impact-robust planner: those of :class:`PlannerConfig` (grid, thrust share, stages,
    solver) and the ones below. Stage 1 maximises delta alone (>= ``min_delta_mps``), stage 2 minimises the
    number of impacts only, and stage 3 the L1 acceleration of all copies."""

    solver_options: SolverOptions = field(default_factory=_ir_budget)
    """As :class:`PlannerConfig`'s, with its own node budget (:data:`DEFAULT_IR_NODE_BUDGET`, 10,000 nodes on two
    threads, the 600 s safety net): the impact-robust model's nodes cost several times the spatially robust
    one's, and its shipped scenarios need at most 1,615 of them."""
    acceleration_weight: float = 0.0
    """As :class:`PlannerConfig`'s, in m/s of delta; 0: none (tie-breaks in stage 1 halved HiGHS's node
    throughput)."""
    impact_weight: float = 0.0
    """As :class:`PlannerConfig`'s, in m/s of delta per impact; 0: none."""
    min_delta_mps: float = 1e-3
    """The smallest delta worth a plan (m/s): a task that cannot tolerate it is infeasible (the final box is
    then smaller than the grid can trim to)."""
    default_final_box: tuple[float, float] = DEFAULT_FINAL_BOX
    """(position, velocity) half-widths (m, m/s) of the final box of objects without a ``[final_box]``."""
    copy_intervals: int | None = None
    """Grid intervals before and after an impact on which the robot's copies may differ (room to reach the
    box vertices within the thrust limits); None: the scenario's ``[planner] copy_intervals``, else 2."""
    disjunctive_resets: bool = True
    """The box resets in Balas' convex-hull form (False: big-M switching, the baseline of
    ``benchmarks/planner.py``)."""
    contact_cones: int | None = 8
    """Room for the disc robot behind every copy's contact (``planners/offline/milp/contact_room.py``): the
    circle of push directions cut into this many cones (>= 4; more: less conservative, more binaries).
    None: the copies are points that meet the object's centre (as before this option; a disc robot may not fit)."""

    def __post_init__(self, *solver_keywords: Any) -> None:
        super().__post_init__(*solver_keywords)
        check_number(self, "min_delta_mps", PlannerError, low=0, low_open=True)
        box = self.default_final_box
        if not (isinstance(box, tuple) and len(box) == 2 and all(is_finite_number(v) and v > 0 for v in box)):
            fail("IRPlannerConfig.default_final_box", box, "a tuple (position_m, velocity_mps) of two finite "
                 "numbers > 0", PlannerError)
        check_integer(self, "copy_intervals", PlannerError, low=1, none="the scenario's hint, else 2")
        check_flag(self, "disjunctive_resets", PlannerError)
        if self.robot_object_separation:
            fail("IRPlannerConfig.robot_object_separation", True, "False: with the impact-robust planner the "
                 "controller keeps robots off objects away from planned impacts", PlannerError)
