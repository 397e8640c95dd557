"""Stage 1 of the spatially robust planner (maximise rho) under model and solver variants, by its work.

Each row solves stage 1 once, with the default budget, and reports its branch-and-bound nodes (the same for
the same model, options and seed on any load, so the variants compare by work, not by a clock that other jobs
share), its time, how it ended and rho: a variant that keeps the model's optimum must give the same rho. Several
seeds per variant, since a MILP's node count changes with its search path as much as with its model. Variants:

- ``default``: the planner as shipped;
- ``threads1``: HiGHS on one thread (the default lets it take both cores);
- ``no_ties``: no acceleration and impact tie-breaks in stage 1's objective (stage 2 still minimises both);
- ``reach``: every control point and object knot bounded by what its speed bound lets it reach from its
  start (and, for a robot with a final position, still reach it from): bounds the rows imply, so the optimum
  stays, that tighten every big-M presolve derives from the bounds.

Usage:

    python -m benchmarks.planner_variants [--scenarios relay] [--variants default,threads1,no_ties,reach]
                                          [--seeds 0,1]
"""

from __future__ import annotations

import argparse
import dataclasses
import os

VARIANTS = ("default", "threads1", "no_ties", "reach")


def reach_bounds(built, scenario) -> None:
    """Tighten the bounds of every robot control point and object knot to the box its speed bound reaches."""
    from planners.offline.milp.trajectories import velocity_bound

    m = built.model
    dt, tf, n = built.grid.dt_s, scenario.tf_s, built.grid.intervals

    def clamp(expr, lo: float, hi: float) -> None:
        (idx,) = expr.terms
        m.col_lo[idx] = max(m.col_lo[idx], lo - 1e-9)
        m.col_hi[idx] = min(m.col_hi[idx], hi + 1e-9)

    for r in built.robots:
        d, vb = r.degree, velocity_bound(r.spec)
        for k in range(n):
            for i in range(d + 1):
                t = k * dt + i * dt / d
                for a in range(2):
                    lo, hi = r.spec.position_m[a] - vb[a] * t, r.spec.position_m[a] + vb[a] * t
                    if r.spec.final_position_m is not None:
                        back = vb[a] * (tf - t)
                        lo, hi = max(lo, r.spec.final_position_m[a] - back), min(hi, r.spec.final_position_m[a] + back)
                    clamp(r.cp[k][i][a], lo, hi)
    for o in built.objects:
        vb = velocity_bound(o.spec)
        for k in range(n + 1):
            for a in range(2):
                clamp(o.x[k][a], o.spec.position_m[a] - vb[a] * k * dt, o.spec.position_m[a] + vb[a] * k * dt)


def stage1(name: str, variant: str, seed: int) -> str:
    from impact_env.transport.scenario import load_scenario
    from planners.offline.config import PlannerConfig
    from planners.offline.solvers import solve
    from planners.offline.spatially_robust import build_model

    scenario = load_scenario(name)
    config = PlannerConfig()
    options = dataclasses.replace(config.solver_options, seed=seed)
    if variant == "threads1":
        options = dataclasses.replace(options, threads=1)
    if variant == "no_ties":
        config = dataclasses.replace(config, acceleration_weight=0.0, impact_weight=0.0)
    built = build_model(scenario, config)
    if variant == "reach":
        reach_bounds(built, scenario)
    result = solve(built.model, config.solver, options)
    rho = "-" if result.x is None else f"{built.rho.value(result.x):.4f}"
    load = " ".join(f"{v:.1f}" for v in os.getloadavg())
    return (f"| {name} | {variant} | {seed} | {result.nodes} | {result.solve_time_s:.1f} | {result.status.value} | "
            f"{rho} | {load} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenarios", default="relay", help="comma-separated shipped names")
    parser.add_argument("--variants", default=",".join(VARIANTS), help=f"comma-separated from {', '.join(VARIANTS)}")
    parser.add_argument("--seeds", default="0,1", help="comma-separated solver seeds")
    args = parser.parse_args()
    variants = [v for v in args.variants.split(",") if v]
    unknown = [v for v in variants if v not in VARIANTS]
    if unknown:
        parser.error(f"unknown variant(s) {', '.join(unknown)}; choose from {', '.join(VARIANTS)}")
    seeds = [int(s) for s in args.seeds.split(",") if s]
    print(f"{os.cpu_count()} CPUs; HiGHS, stage 1 with the default budget\n")
    print("| scenario | variant | seed | nodes | s | ended | rho (m) | load |")
    print("|---|---|---:|---:|---:|---|---:|---|")
    for name in [s for s in args.scenarios.split(",") if s]:
        for seed in seeds:
            for variant in variants:
                print(stage1(name, variant, seed), flush=True)


if __name__ == "__main__":
    main()
