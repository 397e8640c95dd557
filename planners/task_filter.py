"""Keep a generated task only if the MILP planner proves it can be done: ``impact-env filter``.

    verdict, plan = filter_task("gaps", 3)                  # plan is None unless verdict.kept
    filter_tasks("gaps", range(100), "tasks/gaps")          # <name>.toml + <name>.plan.json per kept task

A task (:mod:`impact_env.transport.generate`) is kept when the spatially robust planner finds, within its
budget, a plan whose robustness rho exceeds :attr:`FilterConfig.min_robustness_m`: a plan is the proof
that the task can be done, so a stage-1 solve cut by the budget before it proved optimality still keeps
the task (its gap is recorded). The budget is a branch-and-bound node count
(:attr:`FilterConfig.node_limit`) on one thread, so the same task gets the same verdict and the same plan
on a busy machine; the time limit is only a safety net, and a verdict it cut says so
(``budget == "time"``). Every verdict records why: ``planned``, ``low_robustness``, ``infeasible``,
``no_plan_in_budget``, ``unflyable_handover`` or ``solver_error``.

This layer is above ``impact_env/``: the generator draws and checks tasks, this module plans them, and
the dataset builder (``baselines/tasks.py``) flies the kept ones.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Iterable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from impact_env.cli_options import add_quiet, check_outputs, output_path
from impact_env.config_checks import check_integer, check_number
from impact_env.errors import ImpactEnvError
from impact_env.results_store import CellStore, atomic_path, write_atomic
from impact_env.transport.generate import FAMILIES, check_family, generate_toml, task_name
from impact_env.transport.scenario import Scenario
from impact_env.transport.scenario_toml import scenario_from_toml
from planners.errors import InfeasiblePlanError, PlannerError, PlanTimeoutError, UnflyableHandoverError
from planners.offline.config import PlannerConfig
from planners.offline.solvers.base import SolverOptions
from planners.offline.spatially_robust import plan_spatially_robust
from planners.plan import Plan

__all__ = ["FilterConfig", "TaskVerdict", "filter_scenario", "filter_task", "filter_tasks", "load_kept",
           "parse_seeds", "register"]

PROVED_GAP = 1e-4  # the planner's default MIP gap: a smaller final gap means stage 1 proved rho optimal


@dataclass(frozen=True)
class FilterConfig:
    """The planner's budget for one task, and what it must prove."""

    node_limit: int = 2000
    """Branch-and-bound nodes of stage 1 (the deterministic budget)."""
    time_limit_s: float = 1800.0
    """Wall-clock safety net of stage 1 (s), far above what the node budget takes on an idle machine (10-60 s);
    a verdict it decided is marked ``budget = "time"``."""
    min_robustness_m: float = 1e-3
    """Keep a task only if the plan's rho exceeds this (m): "rho > 0" beyond the solver's tolerances."""
    threads: int = 1
    """Solver threads (1: the node budget gives the same plan on every run)."""
    seed: int = 0
    """The solver's random seed."""
    contact_cones: int | None = None
    """Keep room for each disc robot behind its contacts (``PlannerConfig.contact_cones``, 8 is the
    impact-robust planner's count): a generated task puts objects near walls, where a plan of point robots can
    ask for pushes no disc robot can give (32 of the first 136 kept throw-and-catch plans). None (the default):
    point robots, as the shipped plans. Measured on those 32 (``python -m benchmarks.contact_room``,
    ``docs/generated_tasks.md#room-for-the-disc-robot``): with 8 cones 11 are kept and 21 refused (the expert
    had delivered 8 of those 21 with their old plans), and planning takes about 4 times as long, so the rows
    stay opt-in until a larger run shows what they buy."""

    def __post_init__(self) -> None:
        check_integer(self, "node_limit", PlannerError, low=1)
        check_number(self, "time_limit_s", PlannerError, low=0, low_open=True)
        check_number(self, "min_robustness_m", PlannerError, low=0)
        check_integer(self, "threads", PlannerError, low=1)
        check_integer(self, "seed", PlannerError, low=0)
        check_integer(self, "contact_cones", PlannerError, low=4, none="point robots")

    def planner_config(self) -> PlannerConfig:
        budget = SolverOptions(node_limit=self.node_limit, time_limit_s=self.time_limit_s, threads=self.threads,
                               seed=self.seed)
        return PlannerConfig(diagnose_infeasibility=False, contact_cones=self.contact_cones, solver_options=budget)


@dataclass
class TaskVerdict:
    """What the planner said about one task (a JSON line of ``verdicts.jsonl``)."""

    name: str
    family: str | None
    seed: int | None
    kept: bool
    reason: str  # planned, low_robustness, infeasible, no_plan_in_budget, unflyable_handover, solver_error
    robustness_m: float | None
    mip_gap: float | None
    proved_optimal: bool
    budget: str  # "nodes" (the deterministic end, or optimal before it) or "time" (the safety net cut it)
    plan_s: float  # wall time of the planner call (build, stages, checks)
    impacts: int
    robots: int
    objects: int
    plan_fingerprint: str | None = None


def filter_scenario(scenario: Scenario, config: FilterConfig | None = None, family: str | None = None,
                    seed: int | None = None) -> tuple[TaskVerdict, Plan | None]:
    """Plan ``scenario`` within the budget; the verdict, and the plan if the task is kept."""
    config = config or FilterConfig()
    start = time.perf_counter()
    plan, reason, budget = None, "planned", "nodes"
    try:
        plan = plan_spatially_robust(scenario, config.planner_config())
    except PlanTimeoutError as exc:  # a plan the safety net cut still proves the task; none: the budget ran out
        plan = exc.plan
        if plan is None:
            reason = "no_plan_in_budget"
        budget = "time" if plan is not None or time.perf_counter() - start >= config.time_limit_s else "nodes"
    except UnflyableHandoverError:
        reason = "unflyable_handover"
    except InfeasiblePlanError:
        reason = "infeasible"
    except PlannerError:  # the solver failed on this task: recorded, so that a long run goes on
        reason = "solver_error"
    elapsed = time.perf_counter() - start
    rho = None if plan is None else float(plan.robustness)
    if rho is not None and not rho > config.min_robustness_m:  # (rho: the plan's)
        reason = "low_robustness"
    kept = reason == "planned"
    verdict = TaskVerdict(
        name=scenario.name, family=family, seed=seed, kept=kept, reason=reason, robustness_m=rho,
        mip_gap=None if plan is None else float(plan.mip_gap),
        proved_optimal=plan is not None and budget == "nodes" and plan.mip_gap <= PROVED_GAP, budget=budget,
        plan_s=elapsed, impacts=0 if plan is None else len(plan.impacts), robots=len(scenario.robots),
        objects=len(scenario.objects), plan_fingerprint=plan.fingerprint() if kept and plan is not None else None)
    return verdict, plan if kept else None


def filter_task(family: str, seed: int, config: FilterConfig | None = None) -> tuple[TaskVerdict, Plan | None]:
    """:func:`filter_scenario` on task ``seed`` of ``family``."""
    scenario = scenario_from_toml(generate_toml(family, seed), source=task_name(family, seed))
    return filter_scenario(scenario, config, family, seed)


def filter_tasks(family: str, seeds: Iterable[int], out: str | Path, config: FilterConfig | None = None,
                 progress: bool = True) -> list[TaskVerdict]:
    """Filter the tasks ``seeds`` of ``family`` into the folder ``out``: ``<name>.toml`` and
    ``<name>.plan.json`` for each kept task, and one line per task in ``verdicts.jsonl`` (seeds already there
    are not planned again, so an interrupted run resumes)."""
    out = Path(out)
    store = CellStore(out / "verdicts.jsonl", key=lambda cell: cell["name"])
    config = config or FilterConfig()
    verdicts = []
    for seed in seeds:
        name = task_name(family, seed)
        cell = store.get(name)
        if cell is not None:
            verdicts.append(TaskVerdict(**cell))
            continue
        text = generate_toml(family, seed)
        verdict, plan = filter_scenario(scenario_from_toml(text, source=name), config, family, seed)
        if plan is not None:
            write_atomic(out / f"{name}.toml", text)
            with atomic_path(out / f"{name}.plan.json") as tmp:
                plan.save(tmp)
        store.put(asdict(verdict))
        verdicts.append(verdict)
        if progress:
            rho = "-" if verdict.robustness_m is None else f"{verdict.robustness_m:.3f} m"
            print(f"  {name}: {verdict.reason} (rho {rho}, {verdict.plan_s:.1f} s)", flush=True)
    return verdicts


def load_kept(folder: str | Path) -> list[tuple[Scenario, Plan, dict[str, Any]]]:
    """The kept tasks of a folder written by :func:`filter_tasks`: (scenario, plan, verdict) in seed order."""
    folder = Path(folder)
    store = CellStore(folder / "verdicts.jsonl", key=lambda cell: cell["name"])
    if not store.path.is_file():
        raise ImpactEnvError(f"{folder} has no verdicts.jsonl: filter tasks into it first (impact-env filter)")
    kept = []
    for cell in sorted(store.cells(), key=lambda c: (c["family"] or "", c["seed"] if c["seed"] is not None else -1)):
        if cell["kept"]:
            path = folder / f"{cell['name']}.toml"
            scenario = scenario_from_toml(path.read_text(encoding="utf-8"), source=cell["name"])
            kept.append((scenario, Plan.load(folder / f"{cell['name']}.plan.json"), cell))
    return kept


def parse_seeds(text: str) -> list[int]:
    """``"0:100"`` (0..99), ``"5"`` or ``"1,4,9"`` as a list of seeds."""
    try:
        if ":" in text:
            a, b = text.split(":")
            seeds = list(range(int(a), int(b)))
        else:
            seeds = [int(s) for s in text.split(",") if s.strip()]
    except ValueError:
        raise ImpactEnvError(f"--seeds must be A:B (A..B-1), N or a comma-separated list, got {text!r}") from None
    if not seeds or min(seeds) < 0:
        raise ImpactEnvError(f"--seeds must name at least one seed, all >= 0, got {text!r}")
    return seeds


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``impact-env filter`` (called by :func:`planners.cli.register`)."""
    p = subparsers.add_parser("filter", help="plan generated tasks and keep those the MILP proves doable (rho > 0)",
                              description="Generate tasks SEEDS of a family, plan each with the spatially robust "
                                          "MILP within a node budget, and keep those with a plan of rho > 0: "
                                          "<name>.toml and <name>.plan.json in OUT, one line per task in "
                                          "OUT/verdicts.jsonl (a rerun skips the tasks already there).")
    p.add_argument("--family", required=True, help=f"one of {', '.join(FAMILIES)}")
    p.add_argument("--seeds", default="0:10", help="A:B (seeds A..B-1), N, or a comma-separated list (default 0:10)")
    p.add_argument("--out", required=True, metavar="DIR", type=output_path,
                   help="output folder: the kept tasks, their plans and verdicts.jsonl")
    defaults = FilterConfig()
    p.add_argument("--node-limit", type=int, default=defaults.node_limit,
                   help=f"branch-and-bound nodes per task (default {defaults.node_limit})")
    p.add_argument("--time-limit", type=float, default=defaults.time_limit_s,
                   help=f"safety-net wall-clock limit per task, s (default {defaults.time_limit_s:g})")
    p.add_argument("--min-robustness", type=float, default=defaults.min_robustness_m,
                   help=f"keep a task only if its plan's rho exceeds this, m (default {defaults.min_robustness_m:g})")
    p.add_argument("--contact-cones", type=int, default=defaults.contact_cones or 0, metavar="N",
                   help="keep room for each disc robot behind its contacts, push directions in N cones (8 as "
                        "the impact-robust planner; default 0: point robots, no room kept)")
    add_quiet(p, "no line per task; only the count kept")
    p.set_defaults(func=_run)


def _run(args: argparse.Namespace) -> int:
    seeds = parse_seeds(args.seeds)
    check_family(args.family, seeds[0])
    check_outputs(folders={"--out": args.out})  # before any plan
    config = FilterConfig(node_limit=args.node_limit, time_limit_s=args.time_limit,
                          min_robustness_m=args.min_robustness, contact_cones=args.contact_cones or None)
    verdicts = filter_tasks(args.family, seeds, args.out, config, progress=not args.quiet)
    kept = sum(v.kept for v in verdicts)
    reasons: dict[str, int] = {}
    for v in verdicts:
        reasons[v.reason] = reasons.get(v.reason, 0) + 1
    print(f"kept {kept} of {len(verdicts)} {args.family} tasks ({100 * kept / len(verdicts):.0f} %): "
          + json.dumps(reasons))
    return 0
