"""The ``impact-env plan`` subcommand: run the spatially robust or the impact-robust planner on a scenario.

    impact-env plan SCENARIO [--planner sr|ir] [--solver highs|scip|gurobi] [--node-limit N] [--time-limit S]
                    [--mip-gap G]
                    [--threads N] [--intervals N] [--degree D] [--copy-intervals W] [--smooth]
                    [--json plan.json] [--plot plan.png] [--out DIR] [--quiet]
    impact-env plan corridor,relay,two_objects [--planner sr|ir] --out plans/ [--engine ray]

``--out DIR`` writes ``<scenario>.json`` and ``<scenario>.png`` into DIR; ``--json`` and ``--plot`` are the
single files (for one scenario). A comma-separated list of scenarios is planned side by side on the sweep
engine (planners/offline/batch.py), one ``<scenario>.json`` and ``.png`` each in ``--out``. Every output path is
checked before the solve.

Joins ``impact-env`` through the ``impact_env.commands`` entry point (``register``), with ``impact-env filter``
(:mod:`planners.task_filter`); prints the model size,
progress at most once a second, then the robustness, solve time, gap and one line per planned impact. Exit
codes: 0 plan found (optimal within the gap); 3 node budget or time limit reached with a plan (still written,
with a warning giving its gap); 2 any error that ``impact_env.cli.main`` reports in one line (bad options,
infeasible task, unsupported STL, solver missing, no plan within the time limit).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import textwrap
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from impact_env.cli_options import (
    add_files,
    add_out,
    add_quiet,
    add_seed,
    check_outputs,
    deprecated,
    in_folder,
    legacy_file_out,
)
from impact_env.figures import png_path
from impact_env.transport.scenario import MAX_PLANNER_INTERVALS, MAX_ROBOT_DEGREE, MIN_ROBOT_DEGREE
from planners.errors import PlannerError, PlanTimeoutError
from planners.offline.solvers import SOLVERS as SOLVER_NAMES

if TYPE_CHECKING:
    from impact_env.transport.scenario import Scenario
    from planners.offline.config import PlannerConfig
    from planners.offline.solvers.base import Progress, SolverOptions
    from planners.plan import Plan

EXIT_TIME_LIMIT = 3
PLANNERS = ("sr", "ir")


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``plan`` subcommand to ``impact-env`` (entry point of the ``impact_env.commands`` group)."""
    p = subparsers.add_parser("plan", help="plan impacts and trajectories with a MILP planner (spatially robust "
                              "or impact-robust)",
                              description="Plan when, where and with which robot to hit each object, with maximal "
                                          "STL robustness (--planner sr) or maximal tolerated post-impact velocity "
                                          "error (--planner ir): a MILP, proved optimal.")
    p.add_argument("scenario", help="shipped name or path to a .toml file")
    p.add_argument("--planner", default="sr",
                   help="sr: maximise the STL spatial robustness rho (default); ir: maximise delta, the "
                        "post-impact velocity error every impact may have (m/s per axis) with the task and the "
                        "scenario's [final_box] still guaranteed")
    # a free string, checked in the handler, so that a typo is a one-line error rather than argparse usage
    p.add_argument("--solver", default="highs", help=f"MILP solver: one of {', '.join(SOLVER_NAMES)} (default highs)")
    p.add_argument("--time-limit", type=float, default=None, metavar="S",
                   help="solver wall-clock limit in seconds, a safety net (default: the planner's, 600 for sr, 60 for "
                        "ir); on reaching it the best plan is kept")
    p.add_argument("--node-limit", type=int, default=None, metavar="N",
                   help="branch-and-bound node budget of the robustness stage: the same work, so the same plan, on a "
                        "busy machine (default: the planner's, 20000 for sr, none for ir); on reaching it the best "
                        "plan is kept")
    p.add_argument("--mip-gap", type=float, default=1e-4, metavar="G",
                   help="relative optimality gap at which the solver stops (default 1e-4)")
    p.add_argument("--threads", type=int, default=None, metavar="N",
                   help="solver threads; the plan depends on the count (default: the planner's, 2 for sr, the "
                        "solver's choice for ir)")
    p.add_argument("--intervals", type=int, default=None, metavar="N",
                   help="time-grid intervals; impacts happen at its knots (default: the scenario's [planner] hint)")
    p.add_argument("--degree", type=int, default=None, metavar="D",
                   help="degree of the robots' Bezier curves (default: the scenario's [planner] hint)")
    p.add_argument("--copy-intervals", type=int, default=None, metavar="W",
                   help="ir only: grid intervals before and after an impact on which the robot's contingency "
                        "copies may differ (default: the scenario's [planner] hint, else 2)")
    p.add_argument("--smooth", action="store_true",
                   help="finish with a QP that minimises squared accelerations (Eq. 28); slower (1-30 s)")
    p.add_argument("--refine-nodes", type=int, default=20, metavar="N",
                   help="branch-and-bound nodes for the second stage (fewest impacts, least acceleration, rho "
                        "kept); a node count, not a time, so the plan is the same on a busy machine; 0 skips it "
                        "(default 20)")
    add_seed(p, "solver random seed (solve times vary with it)")
    add_out(p, "<scenario>.json (the plan) and <scenario>.png (its figure), for one scenario or a list")
    add_files(p, json="the plan as JSON (planners.plan.Plan.save)",
              plot="a PNG of the plan: xy view, positions and velocities over time")
    add_quiet(p, "no header and no progress lines; only the result")
    from planners.tether.cli import add_arguments as add_tether_arguments

    add_tether_arguments(p)  # a tether station (impact-env plan L) is planned by planners/tether/cli.py
    from impact_env.sweep import add_engine_arguments

    add_engine_arguments(p)  # a list of scenarios (impact-env plan a,b,c) is planned side by side
    p.set_defaults(func=_cmd_plan)
    from planners.task_filter import register as register_filter

    register_filter(subparsers)  # impact-env filter: generated tasks kept if the MILP plans them


def _planner(args: argparse.Namespace, common: dict[str, Any]) -> tuple[
        PlannerConfig, Callable[[Scenario, Any], Any], Callable[[Scenario, Any], Plan]]:
    """(config, build(scenario, config) -> model, plan(scenario, config) -> Plan) of ``--planner``."""
    from planners.offline.config import IRPlannerConfig, PlannerConfig
    from planners.offline.impact_robust import build_ir_model, plan_impact_robust
    from planners.offline.spatially_robust import build_model, plan_spatially_robust

    if args.planner == "ir":
        return IRPlannerConfig(copy_intervals=args.copy_intervals, **common), build_ir_model, plan_impact_robust
    return PlannerConfig(**common), build_model, plan_spatially_robust


def _cmd_plan(args: argparse.Namespace) -> int:
    from impact_env.tether.station import is_station_file
    from impact_env.transport.scenario import load_scenario
    if "," in args.scenario:
        return _plan_list(args)
    legacy_file_out(args, "--json", (".json",))
    name = Path(args.scenario).stem if args.scenario.endswith(".toml") else args.scenario
    args.json = in_folder(args, "--json", f"{name}.json")
    args.plot = in_folder(args, "--plot", f"{name}.png")
    if is_station_file(args.scenario):
        from planners.tether.cli import plan_station

        check_outputs({"--json": args.json, "--plot": args.plot, "--drh": args.drh}, {"--out": args.out})
        args.plot = args.plot and str(png_path(args.plot))
        return plan_station(args)

    _check_options(args)
    scenario = load_scenario(args.scenario)
    check_outputs({"--json": args.json, "--plot": args.plot}, {"--out": args.out})
    args.plot = args.plot and str(png_path(args.plot))
    say = (lambda text: None) if args.quiet else (lambda text: print(text, flush=True))
    budget = _budget(args, progress=None if args.quiet else progress_printer())
    common = dict(intervals=args.intervals, robot_degree=args.degree, smooth=args.smooth, solver=args.solver,
                  solver_options=budget, refine_nodes=args.refine_nodes)
    config, build, plan_fn = _planner(args, common)

    say(f"plan {scenario.name}: {len(scenario.robots)} robot(s), {len(scenario.objects)} object(s), "
        f"e = {scenario.restitution:g}, tf = {scenario.tf_s:g} s")
    say(textwrap.fill(f"task: {' '.join(scenario.task.split())}", width=100, subsequent_indent="      "))
    if not args.quiet:
        # a separate build only to show the model size before the (possibly long) solve; it costs ~0.1 s
        built = build(scenario, config)
        m = built.model
        limit = _limits(budget)
        say(f"model: {built.grid.intervals} intervals, robot degree {built.robots[0].degree}: {m.n_binaries} "
            f"binaries, {m.n_vars} variables, {m.n_rows} rows (built in {built.build_time_s:.2f} s)")
        goal = "delta, the tolerated post-impact velocity error" if args.planner == "ir" else "robustness rho"
        say(f"solving with {args.solver} ({limit}, mip gap {args.mip_gap:g}): maximise {goal}")

    code = 0
    start = time.perf_counter()
    try:
        plan = plan_fn(scenario, config)
    except PlanTimeoutError as exc:
        if exc.plan is None:
            raise
        plan = exc.plan
        gap = "unknown" if exc.mip_gap is None else f"{100 * exc.mip_gap:.2f}%"
        print(f"impact-env: warning: time limit of {budget.time_limit_s:g} s reached with gap {gap}; "
              f"keeping the best plan found", file=sys.stderr, flush=True)
        code = EXIT_TIME_LIMIT
    if plan.stats.get("stage1_status") == "node_limit":
        print(f"impact-env: warning: node budget of {budget.node_limit} nodes reached with gap "
              f"{100 * plan.mip_gap:.2f}%; keeping the best plan found", file=sys.stderr, flush=True)
        code = EXIT_TIME_LIMIT

    print(format_summary(plan, wall_s=time.perf_counter() - start))
    if args.json:
        print(f"wrote {plan.save(args.json)}")
    if args.plot:
        from planners.plan.plotting import plot_plan

        plot_plan(scenario, plan, args.plot)
        print(f"wrote {args.plot}")
    return code


def _plan_list(args: argparse.Namespace) -> int:
    """``impact-env plan a,b,c [--out DIR] [--plot DIR] [--engine ray]``: one job per scenario; exit 0 if every
    plan was found, 3 if one hit the time limit (its best plan kept), 2 if one has none."""
    from impact_env.sweep import engine_config, open_engine
    from impact_env.tether.station import is_station_file
    from planners.offline.batch import plan_scenarios
    from planners.offline.config import IRPlannerConfig, PlannerConfig

    names = [n.strip() for n in args.scenario.split(",") if n.strip()]
    stations = [n for n in names if is_station_file(n)]
    if stations:
        raise PlannerError(f"plan tether stations one at a time ({', '.join(stations)}); lists are for impact "
                           "scenarios")
    if args.json is not None:
        raise PlannerError("a list of scenarios writes one plan per scenario: give --out DIR, not --json")
    figures = args.out
    if args.plot is not None:  # 0.2: --plot DIR for a list
        deprecated(f"--plot {args.plot} (a folder) for a list", "--out DIR, which holds the figures too")
        figures = args.plot
    _check_options(args)
    check_outputs(folders={"--out": args.out, "--plot": figures})
    budget = _budget(args)
    common = dict(intervals=args.intervals, robot_degree=args.degree, smooth=args.smooth, solver=args.solver,
                  solver_options=budget, refine_nodes=args.refine_nodes)
    config = (IRPlannerConfig(copy_intervals=args.copy_intervals, **common) if args.planner == "ir"
              else PlannerConfig(**common))
    with open_engine(engine_config(args), n_jobs=len(names)) as engine:
        if not args.quiet:
            print(f"planning {len(names)} scenarios on {engine.describe()}", flush=True)
        outcomes = plan_scenarios(names, config, engine)
    code = 0
    for o in outcomes:
        print(f"\n== {o.scenario} ({o.wall_s:.1f} s)")
        if o.plan is None:
            print(f"impact-env: error: {o.scenario}: {o.error}", file=sys.stderr, flush=True)
            code = 2
            continue
        if o.timed_out or o.plan.stats.get("stage1_status") == "node_limit":
            limit = "time limit" if o.timed_out else "node budget"
            print(f"impact-env: warning: {o.scenario}: {limit} reached; keeping the best plan found",
                  file=sys.stderr, flush=True)
            code = code or EXIT_TIME_LIMIT
        print(format_summary(o.plan) + f"\nplan fingerprint {o.plan.fingerprint()}")
        if args.out:
            print(f"wrote {o.plan.save(Path(args.out) / f'{o.scenario}.json')}")
        if figures:
            from impact_env.transport.scenario import load_scenario
            from planners.plan.plotting import plot_plan

            plot_plan(load_scenario(o.scenario), o.plan, Path(figures) / f"{o.scenario}.png")
            print(f"wrote {Path(figures) / f'{o.scenario}.png'}")
    return code


def _budget(args: argparse.Namespace, progress: Callable[[Progress], None] | None = None) -> SolverOptions:
    """Stage 1's solver budget: the planner's default, with the limits the options give."""
    from planners.offline.config import IRPlannerConfig, PlannerConfig

    default = (IRPlannerConfig() if args.planner == "ir" else PlannerConfig()).solver_options
    given = (("time_limit_s", args.time_limit), ("node_limit", args.node_limit), ("threads", args.threads))
    limits = {k: v for k, v in given if v is not None}
    return dataclasses.replace(default, mip_gap=args.mip_gap, seed=args.seed, progress=progress, **limits)


def _limits(budget: SolverOptions) -> str:
    """E.g. ``node budget 20000, time limit 600 s``."""
    nodes = "no node budget" if budget.node_limit is None else f"node budget {budget.node_limit}"
    return nodes + (", no time limit" if budget.time_limit_s is None else f", time limit {budget.time_limit_s:g} s")


def _check_options(args: argparse.Namespace) -> None:
    """Reject option values the planner would otherwise fail on deep inside, with a one-line message."""
    if args.planner not in PLANNERS:
        raise PlannerError(f"unknown planner {args.planner!r}; choose one of: {', '.join(PLANNERS)}")
    if args.copy_intervals is not None and args.planner != "ir":
        raise PlannerError("--copy-intervals applies to the impact-robust planner only (--planner ir)")
    if args.copy_intervals is not None and args.copy_intervals < 1:
        raise PlannerError(f"--copy-intervals must be >= 1, got {args.copy_intervals}")
    if args.solver not in SOLVER_NAMES:
        from impact_env.catalogue import suggestion

        raise PlannerError(f"unknown solver {args.solver!r}{suggestion(args.solver, SOLVER_NAMES)}; choose one of: "
                           f"{', '.join(SOLVER_NAMES)}")
    if args.time_limit is not None and not (math.isfinite(args.time_limit) and args.time_limit > 0):
        raise PlannerError(f"--time-limit must be a finite number of seconds > 0, got {args.time_limit:g}")
    if args.node_limit is not None and args.node_limit < 1:
        raise PlannerError(f"--node-limit must be >= 1, got {args.node_limit}")
    if not 0.0 <= args.mip_gap < 1.0:
        raise PlannerError(f"--mip-gap must be in [0, 1), got {args.mip_gap:g}")
    if args.threads is not None and args.threads < 1:
        raise PlannerError(f"--threads must be >= 1, got {args.threads}")
    if args.intervals is not None and not 2 <= args.intervals <= MAX_PLANNER_INTERVALS:
        raise PlannerError(f"--intervals must be in 2..{MAX_PLANNER_INTERVALS}, got {args.intervals}")
    if args.degree is not None and not MIN_ROBOT_DEGREE <= args.degree <= MAX_ROBOT_DEGREE:
        raise PlannerError(f"--degree must be in {MIN_ROBOT_DEGREE}..{MAX_ROBOT_DEGREE} (as planner.robot_degree in "
                           f"scenario files), got {args.degree}")
    if not 0 <= args.seed <= 2**31 - 1:
        raise PlannerError(f"--seed must be in 0..{2**31 - 1}, got {args.seed}")
    if args.refine_nodes < 0:
        raise PlannerError(f"--refine-nodes must be >= 0 (0 skips the second stage), got {args.refine_nodes}")


def progress_printer(period_s: float = 1.0, clock: Callable[[], float] = time.monotonic) -> Callable[[Progress], None]:
    """A ``PlannerConfig.progress`` callback printing one line per report, at most once per ``period_s``."""
    last = [-float("inf")]

    def report(p: Progress) -> None:
        now = clock()
        if now - last[0] < period_s:
            return
        last[0] = now
        print(format_progress(p), flush=True)

    return report


def format_progress(p: Progress) -> str:
    """E.g. ``"  t=  3.1 s  incumbent 0.4123  bound 0.5000  gap 17.5%"`` (objective in the model's sense)."""
    incumbent = "   -  " if p.incumbent is None else f"{p.incumbent:.4f}"
    bound = "   -  " if p.bound is None else f"{p.bound:.4f}"
    gap = "-" if p.gap is None else f"{100 * p.gap:.1f}%"
    return f"  t={p.elapsed_s:6.1f} s  incumbent {incumbent}  bound {bound}  gap {gap}"


def format_summary(plan: Plan, wall_s: float | None = None) -> str:
    """The result: robustness, MILP solve time (and the whole planner call's ``wall_s``, which adds the
    build, the smoothing stage and the plan check), gap, and one line per impact."""
    total = "" if wall_s is None else f", {wall_s:.2f} s in all"
    solve = (f"{plan.solver} MILP solve {plan.solve_time_s:.2f} s (build {plan.build_time_s:.2f} s{total})   "
             f"gap {100 * plan.mip_gap:.2f}%")
    if plan.planner == "ir":
        lines = [f"delta = {plan.delta_mps:.5f} m/s (post-impact velocity error tolerated per axis, every impact)   "
                 f"{solve}", f"nominal robustness rho = {plan.robustness:.4f} m (not maximised by this planner)"]
        for name, funnel in plan.funnels.items():
            hp, hv = funnel.position_halfwidth_m[-1], funnel.terminal_velocity_halfwidth_mps
            lines.append(f"{name} ends within +-({hp[0]:.3f}, {hp[1]:.3f}) m and +-({hv[0]:.4f}, {hv[1]:.4f}) m/s of "
                         f"the plan (final box {list(funnel.final_box_m)} m, {list(funnel.final_box_mps)} m/s)")
        kept, trimmed = "delta", "fewest impacts"
    else:
        lines = [f"robustness rho = {plan.robustness:.4f} m   {solve}"]
        kept, trimmed = "rho", "fewest impacts, least acceleration"
    if plan.stats.get("refine_status", "skipped") != "skipped":
        lines.append(f"stage 2 ({trimmed}, {kept} kept): {plan.stats['refine_status']} "
                     f"after {plan.stats['refine_s']:.2f} s, objective {plan.stats['refine_objective']:.4f}")
    lines.append(f"{len(plan.impacts)} impact{'' if len(plan.impacts) == 1 else 's'}:")
    for k, imp in enumerate(plan.impacts, start=1):
        before, after = imp.object_velocity_before, imp.object_velocity_after
        lines.append(f"  I{k}  t = {imp.time_s:6.2f} s  {imp.robot} -> {imp.object}  at ({imp.position[0]:.3f}, "
                     f"{imp.position[1]:.3f}) m  {imp.object} velocity ({before[0]:+.3f}, {before[1]:+.3f}) -> "
                     f"({after[0]:+.3f}, {after[1]:+.3f}) m/s")
    return "\n".join(lines)
