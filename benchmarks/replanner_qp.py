"""The replanner's bounded-segment QPs in closed-loop episodes, and what they do to the episodes.

Flies seeded episodes of the robustness benchmark's combined condition (simulator restitution off by +-0.2,
objects up to 10 cm off their start, 10 % thrust noise; ``ExpertConfig()``) and counts, per episode: the QPs
solved (DAQP calls), the answers DAQP reports as solved, those of them that moved the fixed end-state control
points (more than 1e-9 m: DAQP's answer to an infeasible QP, darnstrom/daqp#82), and the segments
``bounded_segment`` handed on that miss the end state they were asked for (by more than 1e-6 m), with the
largest miss. With ``--ref`` it flies the same episodes with a git commit's ``impact_env`` and ``planners``
(exported to a temporary folder; its episodes run in a Python of their own that imports them,
:func:`benchmarks.git_tree.run_in_tree`) in the same run, for a before/after table. One process per episode,
one worker by default. From the repository root:

    python -m benchmarks.replanner_qp [--scenarios relay,two_objects] [--seeds 10] [--ref 07f8b8c]

The plans are the robustness benchmark's (cached in ``--plans``/plans/, computed there if missing). This
module imports the packages (and :mod:`benchmarks.robustness`, which does) only inside its functions, so that
it loads under the reference tree too.
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import shutil
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from benchmarks.git_tree import ROOT, export_tree, run_in_tree, segment_qp_module

COUNTS = ("qp", "daqp_solved", "ends_moved", "segments_off")


def _instrument(counts: dict) -> None:
    """Count inside the replanner's QP (any tree with ``_SegmentQP.solve`` and ``bounded_segment``)."""
    import planners.online.replanner as replanner

    qp_class = segment_qp_module()._SegmentQP
    solve = qp_class.solve

    def counted_solve(self) -> bool:
        ok = solve(self)
        counts["qp"] += 1
        if self._local.buffer.stats()["success"]:
            counts["daqp_solved"] += 1
            arrays = self._local.arrays
            moved = np.abs(arrays["x"][self.fixed] - arrays["lbx"][self.fixed]).max()
            counts["ends_moved"] += bool(moved > 1e-9)
        return ok

    qp_class.solve = counted_solve
    bounded = replanner.bounded_segment

    def checked(p0, v0, p1, v1, t0, t1, *args, **kwargs):
        seg = bounded(p0, v0, p1, v1, t0, t1, *args, **kwargs)
        if seg is not None:
            T = t1 - t0
            d = len(seg.control_points) - 1
            want = np.array([p0, np.add(p0, np.multiply(v0, T / d)), np.subtract(p1, np.multiply(v1, T / d)), p1],
                            dtype=float)
            miss = float(np.abs(seg.control_points[[0, 1, -2, -1]] - want).max())
            if miss > 1e-6:
                counts["segments_off"] += 1
                counts["largest_miss_m"] = max(counts["largest_miss_m"], miss)
        return seg

    replanner.bounded_segment = checked


def _episode(args: tuple) -> dict:
    tree = args[0]
    if tree is not None:  # in a Python of its own that imports the reference commit's packages
        return run_in_tree(tree, "benchmarks.replanner_qp:counted_episode", args)
    return counted_episode(args)


def counted_episode(args: tuple) -> dict:
    """One episode with the replanner's QPs counted, in this process's packages (the env options come with
    the job: the robustness benchmark's combined condition for its seed)."""
    tree, scenario_name, plan_dict, seed, options = args
    from impact_env.rollout import run_episode
    from impact_env.transport.gym_env import TransportEnv
    from impact_env.transport.scenario import load_scenario
    from planners.expert import Expert, ExpertConfig
    from planners.plan import Plan

    counts = dict.fromkeys(COUNTS, 0) | {"largest_miss_m": 0.0}
    _instrument(counts)
    expert = Expert(load_scenario(scenario_name), plan=Plan.from_dict(plan_dict), config=ExpertConfig())
    env = TransportEnv(expert.scenario, **options)
    res = run_episode(env, expert, seed=seed)
    unplanned = sum(expert.report()["unplanned_contacts"].values())
    return {"tree": tree, "scenario": scenario_name, "seed": seed, "success": bool(res.success),
            "robustness": float(res.robustness), "unplanned": unplanned, **counts}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenarios", default="relay,two_objects")
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--ref", default=None, help="also fly this git commit (before/after table)")
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--plans", default=str(ROOT / "results" / "robustness"),
                        help="the robustness benchmark's --out, whose plans/ are used (default: %(default)s)")
    args = parser.parse_args()
    from benchmarks.robustness import env_options, plan_for
    from impact_env.transport.scenario import load_scenario

    names = args.scenarios.split(",")
    plans = {name: plan_for(name, Path(args.plans)) for name in names}
    ref_dir = export_tree(args.ref, prefix="impact_env_qp_") if args.ref else None
    trees = ([ref_dir] if ref_dir else []) + [None]
    scenarios = {name: load_scenario(name) for name in names}
    jobs = [(tree, name, plans[name], seed, env_options(scenarios[name], "combined", 0.0, seed))
            for name in names for seed in range(args.seeds) for tree in trees]
    print(f"{args.seeds} seeds per scenario and tree, combined condition, ExpertConfig(); load average before: "
          f"{' '.join(f'{x:.1f}' for x in os.getloadavg())}\n")
    with ProcessPoolExecutor(max_workers=args.workers, mp_context=multiprocessing.get_context("spawn"),
                             max_tasks_per_child=1) as pool:
        episodes = list(pool.map(_episode, jobs))
    label = {ref_dir: args.ref, None: "this tree"}
    print("| scenario | tree | success | robustness mean (min) | unplanned contacts / ep | QPs / ep | "
          "DAQP solved / ep | of them ends moved / ep | segments off their end state / ep | largest miss m |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for name in names:
        for tree in trees:
            eps = [e for e in episodes if e["scenario"] == name and e["tree"] == tree]
            rob = np.array([e["robustness"] for e in eps])
            per = {k: sum(e[k] for e in eps) / len(eps) for k in COUNTS + ("unplanned",)}
            print(f"| {name} | {label[tree]} | {sum(e['success'] for e in eps)}/{len(eps)} | "
                  f"{rob.mean():+.4f} ({rob.min():+.4f}) | {per['unplanned']:.2f} | {per['qp']:.0f} | "
                  f"{per['daqp_solved']:.0f} | {per['ends_moved']:.0f} | {per['segments_off']:.1f} | "
                  f"{max(e['largest_miss_m'] for e in eps):.3f} |")
    if ref_dir:
        for name in names:
            rob = {tree: {e["seed"]: e["robustness"] for e in episodes if e["scenario"] == name and e["tree"] == tree}
                   for tree in trees}
            moved = {seed: rob[None][seed] - r for seed, r in rob[ref_dir].items() if abs(rob[None][seed] - r) > 1e-9}
            print(f"\n{name}: robustness against {args.ref}, per seed: " +
                  (", ".join(f"seed {seed} {d:+.4f}" for seed, d in sorted(moved.items())) or "all the same"))
    print(f"\nload average after: {' '.join(f'{x:.1f}' for x in os.getloadavg())}")
    if ref_dir:
        shutil.rmtree(ref_dir, ignore_errors=True)


if __name__ == "__main__":
    main()
