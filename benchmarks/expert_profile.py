"""Where one ``Expert.act`` spends its time: wall time per part and per control step (two robots).

Each part is the exclusive time (its own, without the parts it calls) of the functions below, summed over
the episodes' steps and divided by their number; the steps of a mission replan (one MILP solve inside an
``act``) are left out, as in ``benchmarks.expert --timing``. The wrappers cost about 1 us per call (some
40 calls a step), so the wrapped act is a few percent slower than an unwrapped one. ``--ref`` profiles
another commit's ``impact_env`` and ``planners`` in the same run (its episodes interleaved with the current
tree's, one process per episode: :func:`benchmarks.git_tree.run_in_tree`), for a before/after table. From the
repository root:

    python -m benchmarks.expert_profile [--scenario throw_and_catch_exp] [--episodes 4] [--ref 0859ce7]
    python -m benchmarks.expert_profile --ablation    # act time with each ExpertConfig part switched off

Measured with ``--episodes 4 --ref 0859ce7`` (main before the act-time work of issue 9) on the 2-core
machine, one worker, throw_and_catch_exp, default ``ExpertConfig()``, half the episodes nominal and half with
the simulator's restitution off by +-0.1, 5 cm start offsets and 5 % thrust noise; load average 3.5 before
the run (another engineer's jobs beside it, so both columns are inflated alike); ms per step:

| part | before (0859ce7) | after |
|---|---:|---:|
| MPC solver (CasADi sqpmethod + qrqp) | 0.95 | 0.58 |
| MPC setup and readout (Python, numpy<->CasADi) | 0.50 | 0.21 |
| replanner QP solver (DAQP) | 0.59 | 0.11 |
| replanner QP setup (Python) | 0.29 | 0.13 |
| replanner closed form and checks | 0.06 | 0.04 |
| plan sampling | 0.23 | 0.17 |
| reference selection (the rest) | 0.15 | 0.13 |
| keep-offs and segment limits | 0.09 | 0.09 |
| mission monitor | 0.04 | 0.06 |
| identification + impact bookkeeping | 0.00 | 0.00 |
| per-robot loop and observation parsing | 0.13 | 0.12 |
| **act (wrapped), mean** | **3.04** | **1.64** |
| act (wrapped), median | 3.31 | 1.57 |

"Before", the two solver rows include the conversions of a call ``solver(x0=..., p=...)`` with numpy
arguments: CasADi copies each array into a matrix and each result back, about 25 us per array plus 0.1 us
per number, which was 0.2 ms of a 0.25 ms DAQP call and a third of an MPC solve. Both solvers are now called
through CasADi's zero-copy ``Function.buffer`` with numpy arrays bound once (:mod:`planners.online.mpc`,
:mod:`planners.online.replanner`), and the MPC no longer asks for the parameters' multipliers (an extra
derivative evaluation per solve that nothing read). The rest is Python overhead taken out (numpy's argument
handling in ``clip`` and ``linspace``, the Bernstein coefficients rebuilt per call, per-episode constants
recomputed per step). Every change keeps the numbers to the last bit: checked while making them, 14 seeded
episodes over the seven shipped scenarios, nominal and mismatched, flew exactly the actions of 0859ce7.

What the parts beyond the paper cost (``--ablation --episodes 4``, load average 3.6; the difference of
medians is the part's cost; repeated runs moved the small rows by up to 0.05 ms):

| variant | median ms | mean ms | all minus this (median) |
|---|---:|---:|---:|
| all | 1.62 | 2.19 | +0.00 |
| paper | 1.19 | 1.56 | +0.43 |
| all - identification | 1.62 | 2.10 | +0.00 |
| all - mission_replanning | 1.63 | 2.00 | -0.01 |
| all - safe_segments | 1.31 | 1.72 | +0.31 |
| all - aim_final_position | 1.63 | 2.08 | -0.02 |
| all - disc_offset | 1.58 | 2.04 | +0.04 |

Safe segments are nearly all of it (0.31 ms): the replanner tries the segment with its limits first (the
world box, obstacle faces and the other robots' planned paths, sampled at 8 times per try), and the MPC gets
the robot-robot and wall keep-off rows. Mission monitoring predicts and evaluates the task once a second and
at impacts (0.06 ms per step on average in the first table); identification and the final aim cost nothing
measurable.
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import shutil
import time
from collections import Counter
from concurrent.futures import ProcessPoolExecutor

from benchmarks.git_tree import export_tree, run_in_tree, segment_qp_module

PARTS = ("MPC solver (CasADi sqpmethod + qrqp)", "MPC setup and readout (Python, numpy<->CasADi)",
         "replanner QP solver (DAQP)", "replanner QP setup (Python)", "replanner closed form and checks",
         "plan sampling", "reference selection (the rest)", "keep-offs and segment limits", "mission monitor",
         "identification + impact bookkeeping", "per-robot loop and observation parsing")


class _Profile:
    """Exclusive wall time per label; one record per ``act`` (the outermost wrapped call)."""

    def __init__(self) -> None:
        self.step: Counter[str] = Counter()
        self.steps: list[Counter[str]] = []
        self._children: list[float] = []

    def wrap(self, fn, label: str):
        def timed(*args, **kwargs):
            self._children.append(0.0)
            start = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                elapsed = time.perf_counter() - start
                self.step[label] += elapsed - self._children.pop()
                if self._children:
                    self._children[-1] += elapsed
                else:  # an act ended
                    self.step["act"] = elapsed
                    self.steps.append(self.step)
                    self.step = Counter()

        return timed


class _TimedSolver:
    """A CasADi Function whose calls are timed (attributes pass through)."""

    def __init__(self, fn, timed) -> None:
        self._fn, self._timed = fn, timed

    def __call__(self, *args, **kwargs):
        return self._timed(*args, **kwargs)

    def __getattr__(self, name: str):
        return getattr(self._fn, name)


def _instrument(prof: _Profile, expert) -> None:
    """Wrap the parts' functions (names that exist both in the current tree and in the reference commits)."""
    try:  # the expert's module since the planners' layout move; planners.expert before it
        import planners.expert.expert as expert_mod
    except ImportError:
        import planners.expert as expert_mod
    import planners.online.mpc as mpc_mod
    import planners.online.replanner as replanner_mod
    from planners.online.bookkeeping import ImpactBook
    from planners.online.identification import ImpactIdentifier
    from planners.online.mission import MissionPlanner
    from planners.online.reference import ReferenceSelector
    from planners.online.sampling import PlanSampler

    def method(cls, name: str, label: str) -> None:
        setattr(cls, name, prof.wrap(getattr(cls, name), label))

    method(expert_mod.Expert, "act", PARTS[10])
    method(expert_mod.Expert, "_robot_action", PARTS[10])
    method(mpc_mod.FreeflyerMPC, "solve", PARTS[1])
    if hasattr(mpc_mod, "_SolverCall"):  # called through the zero-copy buffer
        method(mpc_mod._SolverCall, "__call__", PARTS[0])
    else:
        for mpc in expert.mpcs.values():
            mpc._solvers = {k: _TimedSolver(f, prof.wrap(f, PARTS[0])) for k, f in mpc._solvers.items()}
    qp_mod = segment_qp_module()
    if hasattr(qp_mod, "_SegmentQP"):
        method(qp_mod._SegmentQP, "solve", PARTS[2])
    else:
        qp = qp_mod._qp

        def timed_qp(degree: int, _cache: dict = {}):  # noqa: B006 - one wrapped solver per degree
            if degree not in _cache:
                solver, *rest = qp(degree)
                _cache[degree] = (_TimedSolver(solver, prof.wrap(solver, PARTS[2])), *rest)
            return _cache[degree]

        qp_mod._qp = timed_qp
    replanner_mod.bounded_segment = prof.wrap(replanner_mod.bounded_segment, PARTS[3])
    import planners.online.reference as reference_mod

    reference_mod.replan_segment = prof.wrap(reference_mod.replan_segment, PARTS[4])
    reference_mod.replan_around_impact = prof.wrap(reference_mod.replan_around_impact, PARTS[4])
    method(PlanSampler, "state", PARTS[5])
    if hasattr(PlanSampler, "positions"):  # the other robots' paths, positions only (since issue 22's act work)
        method(PlanSampler, "positions", PARTS[5])
    method(ReferenceSelector, "robot_reference", PARTS[6])
    for name in ("objects_keep_off", "robot_keep_off", "boundary_keep_off", "segment_limits"):
        setattr(expert_mod, name, prof.wrap(getattr(expert_mod, name), PARTS[7]))
    method(expert_mod.Expert, "_other_centers", PARTS[7])
    method(MissionPlanner, "step", PARTS[8])
    method(ImpactIdentifier, "observe", PARTS[9])
    method(ImpactBook, "observe", PARTS[9])


SWITCHES = ("identification", "mission_replanning", "safe_segments", "aim_final_position", "disc_offset")


def _config(variant: str):
    """``all`` (``ExpertConfig()``), ``paper`` or ``all - <switch>``."""
    from planners.expert import ExpertConfig

    if variant == "all":
        return ExpertConfig()
    if variant == "paper":
        return ExpertConfig.paper()
    return ExpertConfig(**{variant.removeprefix("all - "): False})


def _episode(args: tuple) -> dict:
    tree = args[0]
    if tree is not None:  # in a Python of its own that imports the reference commit's packages
        return run_in_tree(tree, "benchmarks.expert_profile:profiled_episode", args)
    return profiled_episode(args)


def profiled_episode(args: tuple) -> dict:
    """One episode with the parts timed, in this process's packages."""
    tree, scenario_name, plan_dict, seed, mismatch, variant = args
    import numpy as np

    # paths every tree since 0.2 has (a reference commit from before the 0.3 layout runs this too)
    from impact_env import load_scenario
    from impact_env.envs import TransportEnv
    from impact_env.rollout import run_episode
    from planners.expert import Expert
    from planners.plan import Plan

    scenario = load_scenario(scenario_name)
    expert = Expert(scenario, plan=Plan.from_dict(plan_dict), config=_config(variant))
    prof = _Profile()
    _instrument(prof, expert)
    options = {}
    if mismatch:
        options = {"restitution": float(np.clip(scenario.restitution + (0.1 if seed % 2 else -0.1), 0, 1)),
                   "initial_position_noise_m": 0.05, "thrust_noise": 0.05}
    res = run_episode(TransportEnv(scenario, **options), expert, seed=seed)
    replans = {round(r["time_s"] / scenario.control_period_s)
               for r in expert.report().get("mission", {}).get("records", [])}
    steps = [dict(s) for k, s in enumerate(prof.steps) if k not in replans]
    return {"tree": tree, "variant": variant, "steps": steps, "success": res.success}


def ablation(args, plan: dict) -> None:
    """Median and mean act time (ms, wrapped as above) of ``all``, ``paper`` and ``all`` minus each part."""
    variants = ["all", "paper"] + [f"all - {name}" for name in SWITCHES]
    jobs = [(None, args.scenario, plan, seed, seed % 2 == 1, v) for seed in range(args.episodes) for v in variants]
    print(f"Expert.act, {args.scenario}: ms per step, {args.episodes} episodes per variant (odd seeds mismatched); "
          f"load average before: {' '.join(f'{x:.1f}' for x in os.getloadavg())}\n")
    acts: dict[str, list[float]] = {v: [] for v in variants}
    with ProcessPoolExecutor(max_workers=args.workers, mp_context=multiprocessing.get_context("spawn"),
                             max_tasks_per_child=1) as pool:
        for r in pool.map(_episode, jobs):
            acts[r["variant"]].extend(1e3 * s["act"] for s in r["steps"])
    median = {v: sorted(a)[len(a) // 2] for v, a in acts.items()}
    print("| variant | median ms | mean ms | all minus this (median) |")
    print("|---|---:|---:|---:|")
    for v in variants:
        print(f"| {v} | {median[v]:.2f} | {sum(acts[v]) / len(acts[v]):.2f} | {median['all'] - median[v]:+.2f} |")
    print(f"\nload average after: {' '.join(f'{x:.1f}' for x in os.getloadavg())}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenario", default="throw_and_catch_exp")
    parser.add_argument("--episodes", type=int, default=4, help="per tree; even seeds nominal, odd mismatched")
    parser.add_argument("--ref", default=None, help="also profile this git commit (before/after table)")
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--variant", default="all", help="all (default), paper, or 'all - <part>'")
    parser.add_argument("--ablation", action="store_true",
                        help="instead: the act time of this tree with each ExpertConfig part switched off")
    args = parser.parse_args()
    from impact_env.transport.scenario import load_scenario
    from planners.offline.spatially_robust import plan_spatially_robust

    plan = plan_spatially_robust(load_scenario(args.scenario)).to_dict()
    if args.ablation:
        ablation(args, plan)
        return
    ref_dir = export_tree(args.ref, prefix="impact_env_profile_") if args.ref else None
    trees = ([ref_dir] if ref_dir else []) + [None]
    jobs = [(tree, args.scenario, plan, seed, seed % 2 == 1, args.variant) for seed in range(args.episodes)
            for tree in trees]
    print(f"Expert.act, {args.variant}, {args.scenario}: exclusive ms per step, {args.episodes} episodes per tree "
          f"(odd seeds mismatched); load average before: {' '.join(f'{x:.1f}' for x in os.getloadavg())}\n")
    results: dict = {tree: [] for tree in trees}
    with ProcessPoolExecutor(max_workers=args.workers, mp_context=multiprocessing.get_context("spawn"),
                             max_tasks_per_child=1) as pool:
        for r in pool.map(_episode, jobs):
            results[r["tree"]].append(r)
    names = {ref_dir: args.ref, None: "this tree"}
    totals = {}
    for tree in trees:
        steps = [s for r in results[tree] for s in r["steps"]]
        totals[tree] = {part: 1e3 * sum(s.get(part, 0.0) for s in steps) / len(steps) for part in PARTS}
        acts = sorted(1e3 * s["act"] for s in steps)
        totals[tree]["act"] = (sum(acts) / len(acts), acts[len(acts) // 2], len(steps),
                               sum(r["success"] for r in results[tree]))
    print("| part | " + " | ".join(names[t] for t in trees) + " |")
    print("|---|" + "---:|" * len(trees))
    for part in PARTS:
        print(f"| {part} | " + " | ".join(f"{totals[t][part]:.2f}" for t in trees) + " |")
    print("| **act (wrapped), mean** | " + " | ".join(f"**{totals[t]['act'][0]:.2f}**" for t in trees) + " |")
    print("| act (wrapped), median | " + " | ".join(f"{totals[t]['act'][1]:.2f}" for t in trees) + " |")
    print("| steps (episodes succeeded) | " + " | ".join(
        f"{totals[t]['act'][2]} ({totals[t]['act'][3]}/{args.episodes})" for t in trees) + " |")
    print(f"\nload average after: {' '.join(f'{x:.1f}' for x in os.getloadavg())}")
    if ref_dir:
        shutil.rmtree(ref_dir, ignore_errors=True)


if __name__ == "__main__":
    main()
