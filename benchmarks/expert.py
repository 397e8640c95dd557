"""Expert controller benchmark: closed-loop success and cost, nominal and under model mismatch.

For each scenario the offline plan is computed once; then episodes are flown by the expert (replanner +
MPC) in the Gymnasium env, in the same run:

- nominal: the simulator matches the planner's model;
- mismatch: the simulator's restitution differs from the planner's by +0.1 or -0.1 (alternating seeds),
  objects start up to 5 cm off their planned position, and thrust has 5 % multiplicative noise.

Prints a markdown table: success rate, final robustness (mean, min), impacts, fuel, MPC solve time per
robot per step (median, p99), replans per episode, and the episode's wall time as a multiple of real
time (simulated seconds per wall second). Episodes run in parallel worker processes. Usage:

    python benchmarks/expert.py [--scenarios corridor,throw_and_catch_exp] [--episodes 50] [--workers 2]
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import statistics
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from impact_env.envs.transport import TransportEnv
from impact_env.rollout import robot_object_impacts, run_episode
from impact_env.scenario import load_scenario, scenario_names
from planners.offline.sr_planner import plan_spatially_robust
from planners.plan import Plan

_WORKER: dict = {}


def _episode(args: tuple[str, dict, int, bool]) -> dict:
    scenario_name, plan_dict, seed, mismatch = args
    from planners.expert import Expert

    if scenario_name not in _WORKER:  # one expert (and its compiled MPCs) per worker process and scenario
        _WORKER[scenario_name] = Expert(load_scenario(scenario_name), plan=Plan.from_dict(plan_dict))
    expert = _WORKER[scenario_name]
    scenario = expert.scenario
    options = {}
    if mismatch:
        options = {"restitution": float(np.clip(scenario.restitution + (0.1 if seed % 2 else -0.1), 0, 1)),
                   "initial_position_noise_m": 0.05, "thrust_noise": 0.05}
    env = TransportEnv(scenario, **options)
    res = run_episode(env, expert, seed=seed)
    return {"success": res.success, "robustness": res.robustness,
            "impacts": len(robot_object_impacts(scenario, res.impacts)), "fuel": res.fuel_Ns,
            "mpc_ms": expert.stats.mpc_ms, "replans": expert.stats.replans,
            "realtime": env.core.time_s / res.wall_time_s, "failures": expert.stats.mpc_failures}


def rows(scenario_name: str, episodes: int, workers: int) -> list[str]:
    scenario = load_scenario(scenario_name)
    plan = plan_spatially_robust(scenario)
    out = []
    # spawn: the parent has already run the planner's solver threads, which a forked worker must not inherit
    with ProcessPoolExecutor(max_workers=workers, mp_context=multiprocessing.get_context("spawn")) as pool:
        for mismatch in (False, True):
            jobs = [(scenario_name, plan.to_dict(), s, mismatch) for s in range(episodes)]
            results = list(pool.map(_episode, jobs))
            ms = np.concatenate([r["mpc_ms"] for r in results])
            rho = [r["robustness"] for r in results]
            label = "e +-0.1, 5 cm, 5 % thrust" if mismatch else "nominal"
            out.append(
                f"| {scenario_name} | {label} | {episodes} | {100 * np.mean([r['success'] for r in results]):.0f}% | "
                f"{np.mean(rho):.3f} ({min(rho):+.3f}) | {statistics.mean(r['impacts'] for r in results):.1f} | "
                f"{statistics.mean(r['fuel'] for r in results):.1f} | "
                f"{np.median(ms):.2f} / {np.percentile(ms, 99):.2f} | "
                f"{statistics.mean(r['replans'] for r in results):.0f} | "
                f"{statistics.median(r['realtime'] for r in results):.0f}x |")
            print(out[-1], flush=True)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenarios", default=",".join(scenario_names()))
    parser.add_argument("--episodes", type=int, default=50)
    parser.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    args = parser.parse_args()
    print(f"{args.episodes} episodes per row, {args.workers} worker processes; planned rho in the planner table\n")
    print("| scenario | simulator | episodes | success | robustness mean (min) | impacts | fuel N s | "
          "MPC ms median / p99 | replans | speed vs real time |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for name in args.scenarios.split(","):
        rows(name, args.episodes, args.workers)


if __name__ == "__main__":
    main()
