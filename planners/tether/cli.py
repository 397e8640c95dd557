"""``impact-env plan STATION``: the tether planners from the command line (called by :mod:`planners.cli`).

    impact-env plan L [--method reachability|smt] [--rule region|line_of_sight] [--json plan.json]
                      [--plot plan.png] [--out DIR] [--drh automaton.drh] [--quiet]

``reachability`` (default) is the exact planner: fewest pulls, or a proof that no plan exists. ``smt`` is the
thesis's divide and conquer with z3 under the anchor ``--rule``. ``--drh`` also writes the thesis's automaton
(``k = 1``) in dReach's language. The plan runs with ``impact-env run L --controller expert --plan plan.json``.

Exit codes: 0 a plan (checked, written with ``--out``); 4 proved infeasible (the exact planner's fixed point:
no sequence of pulls of any length reaches the goal); 5 no plan found within the budget (the exact planner's
``max_pulls`` while its reachable set still grew, or the z3 pipeline's bounds: its message names the region
paths, the rule and z3's verdicts, ``unknown`` being a time-out); 2 bad input (``impact_env.cli.main``'s
one-line error).
"""

from __future__ import annotations

import argparse
import time

EXIT_INFEASIBLE = 4  # proved: no sequence of pulls reaches the goal
EXIT_NO_PLAN = 5  # none found within the budget (not a proof)


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The tether options of ``impact-env plan`` (ignored for impact scenarios)."""
    p.add_argument("--method", default="reachability", choices=("reachability", "smt"),
                   help="stations only: the exact planner (default) or the thesis's z3 pipeline")
    p.add_argument("--rule", default="region", choices=("region", "line_of_sight"),
                   help="stations only, --method smt: the anchors a region may use (the thesis's, or any in sight)")
    p.add_argument("--drh", default=None, help="stations only: also write the thesis's automaton (k = 1) as .drh")


def plan_station(args: argparse.Namespace) -> int:
    from impact_env.tether.station import load_station
    from planners.tether.errors import PlannerError, SmtNoPlanError, TetherInfeasibleError
    from planners.tether.reachability import ReachabilityPlanner

    st = load_station(args.scenario)
    say = (lambda text: None) if args.quiet else (lambda text: print(text, flush=True))
    say(f"plan {st.name}: {st.n_anchors} anchors, k = {st.k} of {st.n_robots} robots, w = {st.pull_speed_mps:g} m/s, "
        f"method {args.method}")
    t0 = time.perf_counter()
    levels = regions = None
    if args.method == "reachability":
        planner = ReachabilityPlanner(st)
        try:
            plan = planner.plan()
        except TetherInfeasibleError as exc:
            print(f"infeasible (proved): {exc}")
            return EXIT_INFEASIBLE
        except PlannerError as exc:
            print(f"no plan within the budget: {exc}")
            return EXIT_NO_PLAN
        levels = planner.levels
    else:
        from planners.tether.automaton import build_thesis_map
        from planners.tether.smt import SmtConfig, plan_smt

        config = SmtConfig(rule=args.rule)
        tmap = build_thesis_map(st, args.rule, config.clearance_m)
        try:
            plan = plan_smt(st, config, tmap=tmap)
        except SmtNoPlanError as exc:
            print(f"no plan within the budget: {exc}")
            return EXIT_NO_PLAN
        regions = tmap.regions
    wall = time.perf_counter() - t0
    plan.check(st)
    print(f"{plan.switches} pulls, path {plan.path_length_m:.2f} m, travel time "
          + ", ".join(f"{plan.travel_time_s(k):.0f} s (k = {k})" for k in (1, 2, 3)) + f"; planned in {wall:.3f} s")
    for i, p in enumerate(plan.pulls, start=1):
        a = st.anchor_positions[p.anchor]
        print(f"  P{i}  anchor {p.anchor} at ({a[0]:.2f}, {a[1]:.2f}): ({p.start_m[0]:.3f}, {p.start_m[1]:.3f}) -> "
              f"({p.end_m[0]:.3f}, {p.end_m[1]:.3f}) m, {p.length_m:.2f} m")
    if args.json:
        print(f"wrote {plan.save(args.json)}")
    if args.plot:
        from planners.tether.plotting import plot_tether_plan

        print(f"wrote {plot_tether_plan(st, plan, args.plot, levels=levels, regions=regions)}")
    if args.drh:
        from planners.tether.automaton import build_automaton, build_thesis_map
        from planners.tether.drh import export_drh

        ha = build_automaton(build_thesis_map(st, args.rule), k=1)
        print(f"wrote {export_drh(ha, args.drh, st.bounds, st.tf_s, max_jumps=None)} ({len(ha.modes)} modes, "
              f"{ha.n_jumps} jumps)")
    return 0
