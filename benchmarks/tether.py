"""Tether planners benchmark: the thesis's pipeline (z3) against the exact planner, and the plans flown.

Per station: the MP3 decomposition's region count; the thesis pipeline's wall time (decomposition, extension,
automaton, divide and conquer with z3, under the thesis's anchor rule and under line of sight), its pulls or why
it found none; the exact planner's cold time (a fresh planner: visibility polygons, radial cells, the levels,
the forward read) and warm time (the same planner again from the start: the levels are kept), its pulls, path
length and travel time with k = 1, 2, 3 (pulling at w plus the attach waits, see planners/tether/plan.py) and
the pulling time of the time-optimal refinement with k robots (planners/tether/timing.py, Eq. 5's model, with
the share of its relaxed activations at 0 or 1); then the tether expert flying it once per fidelity level with
the hold task (success, robustness, time to goal, time at rest in the goal, final speed, winch work,
attachments). The baseline of the exact planner's times is the z3 pipeline measured in the same run; the
literature figure is the thesis's 13 minutes for its full automaton with dReach on "a simple problem".

Timings on a shared machine are noisy (the load average is printed; the CPU seconds of the cold plan are
this process's, less sensitive to the load than the wall time); compare within one run. The planner timings run
in this process, one at a time; the flown episodes (the last two tables) run on the sweep engine
(:mod:`impact_env.sweep`): local worker processes, or Ray tasks with ``--engine ray [--address ADDR]``, with the
same results either way. Usage:

    python -m benchmarks.tether [--stations L,T,my_station.toml,...] [--repeats 3] [--z3-timeout 20] [--no-smt]
                                [--episodes 50] [--engine ray] [--workers 2]

The last table is the expert's success rate over ``--episodes`` seeded episodes per station under ``reel`` with
the winches 10 % slower and 10 % faster than planned and the cargo starting up to 0.3 m from its start point.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np

from benchmarks import open_engine
from impact_env.rollout import run_episode
from impact_env.sweep import add_engine_arguments, engine_config
from impact_env.tether.gym_env import TetherEnv
from impact_env.tether.station import load_station, station_names
from planners.errors import PlannerError
from planners.tether.automaton import build_thesis_map
from planners.tether.expert import TetherExpert
from planners.tether.reachability import ReachabilityPlanner
from planners.tether.smt import SmtConfig, plan_smt
from planners.tether.timing import refine_timing


def exact_times(station, repeats: int):
    """Median wall and CPU (this process) seconds of a cold plan, and wall seconds of a warm one."""
    cold, cold_cpu, warm, plan = [], [], [], None
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        planner = ReachabilityPlanner(station)
        plan = planner.plan()
        cold.append(time.perf_counter() - t0)
        cold_cpu.append(time.process_time() - c0)
        t0 = time.perf_counter()
        planner.plan()
        warm.append(time.perf_counter() - t0)
    return statistics.median(cold), statistics.median(cold_cpu), statistics.median(warm), plan


def smt_row(station, rule: str, timeout_s: float) -> str:
    t0 = time.perf_counter()
    try:
        plan = plan_smt(station, SmtConfig(rule=rule, timeout_s=timeout_s))
        plan.check(station)
        return f"{time.perf_counter() - t0:.2f} s, {plan.switches} pulls"
    except PlannerError as exc:
        why = "no plan (z3 timeouts)" if getattr(exc, "stats", {}).get("unknown") else "no plan"
        return f"{time.perf_counter() - t0:.2f} s, {why}"


def flown(job: tuple[str, str]) -> dict:
    """The station's plan flown once (seed 0) by a fresh tether expert at one fidelity level (a sweep job): the
    hold task's outcome, when the cargo reached the goal, how long it rested there, its final speed and the
    winch work."""
    name, fidelity = job
    station = load_station(name)
    env = TetherEnv(station, fidelity=fidelity)
    expert = TetherExpert(station)
    res = run_episode(env, expert, seed=0)
    info = res.final_info
    env.close()
    return {"success": res.success, "rho": res.robustness, "goal_s": info["time_to_goal_s"],
            "held_s": info["time_at_rest_in_goal_s"], "speed": info["speed_mps"], "work": info["winch_work_J"],
            "snags": info["snags"], "switches": info["switches"]}


def perturbed(job: tuple[str, float, int]) -> dict:
    """One seeded reel episode with the winches ``factor`` times the planned speed, cargo start within 0.3 m; a
    fresh expert per episode, so that the result depends on the job alone (a sweep job)."""
    name, factor, seed = job
    station = load_station(name)
    env = TetherEnv(station, fidelity="reel", pull_speed_mps=station.pull_speed_mps * factor,
                    initial_position_noise_m=0.3)
    res = run_episode(env, TetherExpert(station), seed=seed)
    env.close()
    return {"success": res.success, "switches": res.final_info["switches"], "rho": res.robustness,
            "held_s": res.final_info["time_at_rest_in_goal_s"], "speed": res.final_info["speed_mps"]}


def _label(name: str) -> str:
    """A station's name in the tables (a station file is named by its ``name`` field)."""
    return load_station(name).name


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--stations", default=",".join(station_names()))
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--z3-timeout", type=float, default=20.0, help="z3's limit per check (s)")
    parser.add_argument("--no-smt", action="store_true", help="skip the z3 pipeline (fast run)")
    parser.add_argument("--episodes", type=int, default=50, help="perturbed reel episodes per station (0 skips)")
    add_engine_arguments(parser, default_workers=min(2, os.cpu_count() or 1))
    args = parser.parse_args()
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; times are medians of {args.repeats}")
    print("\n| station | regions | thesis pipeline, z3, region rule | z3, line-of-sight rule | exact cold s (CPU s) | "
          "exact warm s | pulls | path m | travel s k=1 / 2 / 3 | refined pulling s k=1 / 2 / 3 (bang-bang %) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    plans = {}
    for name in args.stations.split(","):
        st = load_station(name)
        regions = len(build_thesis_map(st).regions)
        z_region = "skipped" if args.no_smt else smt_row(st, "region", args.z3_timeout)
        z_sight = "skipped" if args.no_smt else smt_row(st, "line_of_sight", args.z3_timeout)
        cold, cold_cpu, warm, plan = exact_times(st, args.repeats)
        plans[name] = plan
        times = " / ".join(f"{plan.travel_time_s(k):.0f}" for k in (1, 2, 3))
        refined = [refine_timing(st, plan, k) for k in (1, 2, 3)]
        timing = " / ".join(f"{r.total_s:.0f}" if r.status == "optimal" else "-" for r in refined)
        timing += " (" + " / ".join(f"{100 * r.bang_bang_fraction:.0f}" for r in refined) + ")"
        print(f"| {st.name} | {regions} | {z_region} | {z_sight} | {cold:.3f} ({cold_cpu:.3f}) | {warm:.4f} | "
              f"{plan.switches} | {plan.path_length_m:.1f} | {times} | {timing} |", flush=True)
    names = args.stations.split(",")
    with open_engine(engine_config(args)) as engine:
        print("\nThe plans flown by the tether expert in pymunk, the hold task (seed 0): success, robustness (m), "
              "time to goal (s), time at rest in the goal at the end (s), final speed (m/s), winch work (J), "
              "attachments")
        print("\n| station | fidelity | success | robustness m | time to goal s | held s | final speed m/s | "
              "winch work J | attachments |")
        print("|---|---|---|---:|---:|---:|---:|---:|---:|")
        fidelities = ("kinematic", "reel", "force")
        results = iter(engine.map(flown, [(name, fid) for name in names for fid in fidelities]))
        for name in names:
            for fid in fidelities:
                r = next(results)
                goal = "-" if r["goal_s"] is None else f"{r['goal_s']:.0f}"
                print(f"| {_label(name)} | {fid} | {'yes' if r['success'] else 'NO'} | {r['rho']:+.2f} | {goal} | "
                      f"{r['held_s']:.0f} | {r['speed']:.4f} | {r['work']:.1f} | {r['switches']} |", flush=True)
        if args.episodes > 0:
            print(f"\nThe expert under reel, {args.episodes} seeded episodes per cell, cargo start within 0.3 m of its "
                  "start point, the hold task: success rate, mean attachments, mean robustness (m), shortest time "
                  "at rest in the goal at the end (s), largest final speed (m/s)")
            print("\n| station | w 10 % slow | w 10 % fast |")
            print("|---|---|---|")
            factors = (0.9, 1.1)
            jobs = [(name, factor, seed) for name in names for factor in factors for seed in range(args.episodes)]
            results = iter(engine.map(perturbed, jobs))
            for name in names:
                cells = []
                for _ in factors:
                    runs = [next(results) for _ in range(args.episodes)]
                    wins = sum(r["success"] for r in runs)
                    cells.append(f"{wins}/{args.episodes} ({100 * wins / args.episodes:.0f} %), "
                                 f"{np.mean([r['switches'] for r in runs]):.1f}, "
                                 f"{np.mean([r['rho'] for r in runs]):+.2f}, "
                                 f"{min(r['held_s'] for r in runs):.0f}, {max(r['speed'] for r in runs):.4f}")
                print(f"| {_label(name)} | " + " | ".join(cells) + " |", flush=True)
        print(f"\nflown episodes: {engine.describe()}, {engine.placement_summary()}")


if __name__ == "__main__":
    main()
