"""Expert controller benchmark: closed-loop success and cost, nominal and under model mismatch.

For each scenario the offline plan is computed once; then episodes are flown by the expert (replanner +
MPC) in the Gymnasium env, in the same run:

- nominal: the simulator matches the planner's model;
- mismatch: the simulator's restitution differs from the planner's by +0.1 or -0.1 (alternating seeds),
  objects start up to 5 cm off their planned position, and thrust has 5 % multiplicative noise.

Prints a markdown table: success rate, final robustness (mean, min), impacts, fuel, MPC solve time per
robot per step (median, p99), replans per episode, and the episode's wall time as a multiple of real
time (simulated seconds per wall second). Episodes run on the sweep engine (:mod:`impact_env.sweep`): local
worker processes, or Ray tasks with ``--engine ray [--address ADDR]``; the table's columns are the same either
way except the timings (MPC ms, speed vs real time). Usage:

    python -m benchmarks.expert [--scenarios corridor,throw_and_catch_exp] [--episodes 50] [--workers 2]
    python -m benchmarks.expert --engine ray --address auto --episodes 200

``--timing`` instead measures the time of one ``Expert.act`` (both robots) against the stack before this
package's online layer was reworked (``--baseline-ref``, a git commit: its ``impact_env`` and ``planners``
are exported to a temporary folder, and each baseline episode runs in a Python of its own that imports them,
:func:`benchmarks.git_tree.run_in_tree`; this module imports the packages only inside its functions, so that
it loads under that tree too). The stacks' episodes are
interleaved in one pool, so machine load hits all of them alike; the load average is printed with the
table. Mission replan steps are reported apart (a replan is a MILP solve inside one act). It runs on local
processes only (each baseline job needs a fresh process of its own). Both stacks load this tree's scenario
file by its path, so a scenario added after the baseline is timed too, and fly the plan the robustness
benchmark flies (``results/robustness/plans/``, planned and cached there when missing);
``--baseline-ref 0378a64`` is issue 22's baseline.

    python -m benchmarks.expert --timing [--scenarios throw_and_catch_exp] [--episodes 10] [--baseline-ref REF]
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import shutil
import statistics
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from benchmarks.git_tree import export_tree, run_in_tree

if TYPE_CHECKING:
    from impact_env.sweep import Engine

_WORKER: dict = {}


def _episode(args: tuple[str, dict, int, bool]) -> dict:
    scenario_name, plan_dict, seed, mismatch = args
    from impact_env.rollout import robot_object_impacts, run_episode
    from impact_env.transport.gym_env import TransportEnv
    from impact_env.transport.scenario import load_scenario
    from planners.expert import Expert
    from planners.plan import Plan

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


def rows(scenario_name: str, episodes: int, engine: Engine) -> list[str]:
    from impact_env.transport.scenario import load_scenario
    from planners.offline.spatially_robust import plan_spatially_robust

    scenario = load_scenario(scenario_name)
    plan = plan_spatially_robust(scenario)
    out = []
    for mismatch in (False, True):
        jobs = [(scenario_name, plan.to_dict(), s, mismatch) for s in range(episodes)]
        results = list(engine.map(_episode, jobs))
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


BASELINE_REF = "c30bf61"  # main before the online layer was split and sped up (issue 9)


def _timed_episode(args: tuple) -> dict:
    scenario_name, plan_dict, stack, seed, mismatch, baseline_dir = args
    if stack == "baseline":  # in a Python of its own that imports the baseline's packages
        return run_in_tree(baseline_dir, "benchmarks.expert:timed_act", scenario_name, plan_dict, stack, seed,
                           mismatch)
    return timed_act(scenario_name, plan_dict, stack, seed, mismatch)


def timed_act(scenario_name: str, plan_dict: dict, stack: str, seed: int, mismatch: bool) -> dict:
    """One episode of ``stack`` (``baseline``: the tree's default expert), the time of every ``Expert.act``.
    It imports only paths that every tree since 0.2 has (the package's top level, ``impact_env.envs``,
    ``impact_env.rollout``, ``planners.expert``, ``planners.plan``), so a baseline from before the 0.3 layout
    runs too."""
    from impact_env import load_scenario
    from impact_env.envs import TransportEnv
    from impact_env.rollout import run_episode
    from planners.expert import Expert
    from planners.plan import Plan

    key = ("timed", scenario_name, stack)
    if key not in _WORKER:
        kwargs = {}
        if stack != "baseline":
            from planners.expert import ExpertConfig

            kwargs["config"] = ExpertConfig.paper() if stack == "paper" else ExpertConfig()
        _WORKER[key] = Expert(load_scenario(scenario_name), plan=Plan.from_dict(plan_dict), **kwargs)
    expert = _WORKER[key]
    scenario = expert.scenario
    options = {}
    if mismatch:
        options = {"restitution": float(np.clip(scenario.restitution + (0.1 if seed % 2 else -0.1), 0, 1)),
                   "initial_position_noise_m": 0.05, "thrust_noise": 0.05}
    res = run_episode(TransportEnv(scenario, **options), expert, seed=seed)
    replan_steps = []
    if stack == "all":  # mission re-plans and station keeping's trims: a MILP solve inside one act
        mission = expert.report().get("mission", {})
        records = mission.get("records", []) + mission.get("trim_records", [])
        replan_steps = [round(r["time_s"] / scenario.control_period_s) for r in records]
    return {"stack": stack, "act_ms": res.controller_ms, "replan_steps": replan_steps, "success": res.success}


def timing(scenarios: list[str], episodes: int, workers: int, ref: str) -> None:
    from benchmarks.robustness import RESULTS, plan_for
    from impact_env.transport import scenarios as shipped

    baseline_dir = export_tree(ref, prefix="impact_env_baseline_")
    stacks = ("baseline", "paper", "all")
    print(f"Expert.act wall time per step (ms), two robots; baseline = {ref}; {episodes} episodes per stack and "
          f"condition, interleaved over {workers} workers; load average before: "
          f"{' '.join(f'{x:.1f}' for x in os.getloadavg())}\n")
    print("| scenario | simulator | stack | steps | median ms | p99 ms | max ms | success |")
    print("|---|---|---|---:|---:|---:|---:|---:|")
    ctx = multiprocessing.get_context("spawn")
    for name in scenarios:
        plan = plan_for(name, RESULTS)
        path = Path(shipped.__file__).parent / f"{name}.toml"  # by path: the baseline may not ship it
        path = str(path if path.exists() else Path(name).resolve())
        for mismatch in (False, True):
            # one pool per stack kind would let them run at different times; instead every worker gets
            # jobs of all three stacks in turn (a baseline job re-imports its packages, so it goes first
            # in a fresh pool of its own only when workers cannot be shared: here each job decides)
            jobs = [(path, plan, stack, seed, mismatch, baseline_dir) for seed in range(episodes) for stack in stacks]
            results: dict[str, list[dict]] = {s: [] for s in stacks}
            with ProcessPoolExecutor(max_workers=workers, mp_context=ctx, max_tasks_per_child=1) as pool:
                for r in pool.map(_timed_episode, jobs):
                    results[r["stack"]].append(r)
            for stack in stacks:
                rs = results[stack]
                ms = np.concatenate([r["act_ms"] for r in rs])
                replan = np.zeros(len(ms), dtype=bool)
                offset = 0
                for r in rs:
                    for k in r["replan_steps"]:
                        if k < len(r["act_ms"]):
                            replan[offset + k] = True
                    offset += len(r["act_ms"])
                steady = ms[~replan]
                label = "e +-0.1, 5 cm, 5 % thrust" if mismatch else "nominal"
                print(f"| {name} | {label} | {stack} | {len(steady)} | {np.median(steady):.2f} | "
                      f"{np.percentile(steady, 99):.2f} | {steady.max():.1f} | "
                      f"{100 * np.mean([r['success'] for r in rs]):.0f}% |", flush=True)
                if replan.any():
                    print(f"| {name} | {label} | {stack}: mission replan steps | {int(replan.sum())} | "
                          f"{np.median(ms[replan]):.0f} | | {ms[replan].max():.0f} | |", flush=True)
    print(f"\nload average after: {' '.join(f'{x:.1f}' for x in os.getloadavg())}")
    shutil.rmtree(baseline_dir, ignore_errors=True)


def main() -> None:
    from benchmarks import open_engine
    from impact_env.sweep import add_engine_arguments, engine_config
    from impact_env.transport.scenario import scenario_names

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenarios", default=",".join(scenario_names()))
    parser.add_argument("--episodes", type=int, default=50)
    add_engine_arguments(parser, default_workers=min(2, os.cpu_count() or 1))
    parser.add_argument("--timing", action="store_true", help="act time against --baseline-ref (see the doc)")
    parser.add_argument("--baseline-ref", default=BASELINE_REF)
    args = parser.parse_args()
    if args.timing:
        if args.engine != "local":
            raise SystemExit("--timing runs on local processes only (each baseline job needs its own process)")
        names = args.scenarios.split(",") if args.scenarios != ",".join(scenario_names()) else ["throw_and_catch_exp"]
        timing(names, args.episodes, args.workers, args.baseline_ref)
        return
    with open_engine(engine_config(args)) as engine:
        print(f"{args.episodes} episodes per row on {engine.describe()}; planned rho in the planner table\n")
        print("| scenario | simulator | episodes | success | robustness mean (min) | impacts | fuel N s | "
              "MPC ms median / p99 | replans | speed vs real time |")
        print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|")
        for name in args.scenarios.split(","):
            rows(name, args.episodes, engine)
        print(f"\n{engine.placement_summary()}")


if __name__ == "__main__":
    main()
