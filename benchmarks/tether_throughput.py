"""Tether environment throughput: env-steps/s of the tether envs against the bare pymunk loop of a reference commit.

The bare loop is the cargo disc, the wall segments and two slide joints reeled in every substep (the ``reel``
physics without line-of-sight checks, STL, observations or rules); each env row pulls with two tethers the same
way (two attaches, then keeps), and every loop starts a fresh world every 60 steps. The reference is that bare
loop as ``benchmarks/env_throughput.py`` defined it at commit ``--reference`` (0378a64), run from that commit's
own tree (``git archive``) in a child process between the rows of each repeat; the bare loop of this checkout
is a row too, and so is the kinematic env with its compiled substep loop off (:mod:`impact_env.tether.native`:
the Python loop a build without a C compiler runs). ``--clock cpu`` times with this process's CPU time instead of
the wall clock (on a machine other jobs keep busy, the wall clock measures the scheduler). Usage:

    python -m benchmarks.tether_throughput [--station L] [--steps 5000] [--repeats 3] [--reference 0378a64]
                                           [--clock wall|cpu]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pymunk

import impact_env  # noqa: F401  (registers the environments)
from impact_env.tether import native
from impact_env.tether.gym_env import TetherEnv
from impact_env.tether.pettingzoo_env import TetherParallelEnv
from impact_env.tether.station import load_station

TETHER_EPISODE_STEPS = 60  # a fresh world this often, so that both tethers pull through every measured step
REFERENCE = "0378a64"  # the commit whose bare tether loop is the reference of the tether table
ROOT = Path(__file__).resolve().parents[1]
# the child that runs the reference commit's bare_tether_loop in its own tree: nothing of this checkout imported
_CHILD = """
import json, sys, time
import _reference_env_throughput as m
if sys.argv[3] == "cpu":
    m.time.perf_counter = time.process_time
from impact_env.station import load_station
print(json.dumps(m.bare_tether_loop(load_station(sys.argv[1]), int(sys.argv[2]))))
"""


def _two_visible_anchors(station) -> tuple[int, int]:
    """The two anchors in line of sight of the start that are farthest from it (long pulls)."""
    start = np.array(station.cargo.start_m)
    visible = np.flatnonzero(station.line_of_sight(station.cargo.start_m))
    far = sorted(visible, key=lambda j: -np.linalg.norm(station.anchor_positions[j] - start))
    return int(far[0]), int(far[1])


def bare_tether_loop(station, steps: int) -> float:
    """Steps/s of pymunk alone: cargo disc, wall segments, two slide joints whose length shrinks every substep."""
    anchors = [tuple(station.anchor_positions[j]) for j in _two_visible_anchors(station)]
    dt = station.control_period_s / station.substeps
    w = station.pull_speed_mps
    start = time.perf_counter()
    for k in range(steps):
        if k % TETHER_EPISODE_STEPS == 0:
            space = pymunk.Space()
            space.damping = 1.0
            space.iterations = 30
            cargo = pymunk.Body(station.cargo.mass_kg, pymunk.moment_for_circle(station.cargo.mass_kg, 0.0,
                                                                                station.cargo.radius_m))
            cargo.position = station.cargo.start_m
            space.add(cargo, pymunk.Circle(cargo, station.cargo.radius_m),
                      *[pymunk.Segment(space.static_body, a, b, 0.0) for a, b in station.walls])
            joints = []
            for a in anchors:
                joint = pymunk.SlideJoint(space.static_body, cargo, a, (0.0, 0.0), 0.0, 1e9)
                joint.max_force = station.winch_force_limit_N
                joint.error_bias = 0.0
                joints.append(joint)
            space.add(*joints)
        for _ in range(station.substeps):
            p, v = cargo.position, cargo.velocity
            q = (p.x + v.x * dt, p.y + v.y * dt)
            for joint, (ax, ay) in zip(joints, anchors):
                joint.max = max(0.0, math.hypot(ax - q[0], ay - q[1]) - w * dt)
            space.step(dt)
        state = (cargo.position, cargo.velocity)  # read the body, as the env does
    del state
    return steps / (time.perf_counter() - start)


def tether_gym(station, steps: int, fidelity: str) -> float:
    env = TetherEnv(station, fidelity=fidelity, max_active=2)
    a, b = _two_visible_anchors(station)
    attach, keep = [2 + a, 2 + b] + [0] * (station.n_robots - 2), [0] * station.n_robots
    start = time.perf_counter()
    for k in range(steps):
        if k % TETHER_EPISODE_STEPS == 0:
            env.reset(seed=k)
        env.step(attach if k % TETHER_EPISODE_STEPS == 0 else keep)
    return steps / (time.perf_counter() - start)


def tether_gym_python_loop(station, steps: int) -> float:
    """tether_gym at kinematic fidelity with the compiled substep loop off (the Python loop it falls back to)."""
    with native.disabled():
        return tether_gym(station, steps, "kinematic")


def tether_pettingzoo(station, steps: int, fidelity: str) -> float:
    env = TetherParallelEnv(station, fidelity=fidelity, max_active=2)
    a, b = _two_visible_anchors(station)
    agents = env.possible_agents
    attach = {agents[0]: 2 + a, agents[1]: 2 + b}
    start = time.perf_counter()
    for k in range(steps):
        if k % TETHER_EPISODE_STEPS == 0:
            env.reset(seed=k)
        env.step(attach if k % TETHER_EPISODE_STEPS == 0 else {})
    return steps / (time.perf_counter() - start)


def reference_tree(ref: str) -> Path:
    """``ref``'s impact_env and planners (benchmarks.git_tree.export_tree) with its env_throughput.py beside them."""
    from benchmarks.git_tree import export_tree

    tree = Path(export_tree(ref, prefix="impact_env_throughput_ref_"))
    source = subprocess.run(["git", "-C", str(ROOT), "show", f"{ref}:benchmarks/env_throughput.py"], check=True,
                            capture_output=True, text=True).stdout
    (tree / "_reference_env_throughput.py").write_text(source)
    return tree


def reference_bare_loop(tree: Path, station: str, steps: int, clock: str) -> float:
    """Steps/s of the reference commit's bare tether loop, in a child process that imports only that tree."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    done = subprocess.run([sys.executable, "-c", _CHILD, station, str(steps), clock], cwd=tree, env=env,
                          capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"the reference bare loop failed in {tree}:\n{done.stderr[-2000:]}")
    return float(json.loads(done.stdout.strip().splitlines()[-1]))


def tether_table(station, steps: int, repeats: int, ref: str, clock: str) -> dict[str, float]:
    """The tether table: each repeat runs the reference bare loop, then every row once; medians over repeats,
    ratios to the reference. Returns label -> median steps/s."""
    tree = reference_tree(ref)
    rows = [(f"bare pymunk loop at {ref} (cargo, walls, 2 slide joints reeled in)",
             lambda: reference_bare_loop(tree, station.name, steps, clock)),
            ("bare pymunk loop at this commit", lambda: bare_tether_loop(station, steps)),
            *[(f"Tether Gymnasium env, {fid}, 2 tethers", lambda fid=fid: tether_gym(station, steps, fid))
              for fid in ("kinematic", "reel", "force")],
            ("Tether Gymnasium env, kinematic, 2 tethers, Python loop (compiled loop off)",
             lambda: tether_gym_python_loop(station, steps)),
            ("Tether PettingZoo env, reel, 2 tethers", lambda: tether_pettingzoo(station, steps, "reel"))]
    rates: dict[str, list[float]] = {label: [] for label, _ in rows}
    for _ in range(repeats):
        for label, fn in rows:
            rates[label].append(fn())
    shutil.rmtree(tree, ignore_errors=True)
    medians = {label: statistics.median(v) for label, v in rates.items()}
    base = medians[rows[0][0]]
    print("| loop | env-steps/s | us/step | vs the bare loop at " + ref + " |")
    print("|---|---:|---:|---:|")
    for label, rate in medians.items():
        print(f"| {label} | {rate:,.0f} | {1e6 / rate:.1f} | {rate / base:.2f} |", flush=True)
    return medians


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--station", default="L")
    parser.add_argument("--steps", type=int, default=5000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--reference", default=REFERENCE, help="the commit whose bare tether loop is the reference")
    parser.add_argument("--clock", choices=("wall", "cpu"), default="wall",
                        help="wall clock (perf_counter, as the loops define it) or this process's CPU time")
    args = parser.parse_args()
    if args.clock == "cpu":
        time.perf_counter = time.process_time  # every loop here reads the clock through time.perf_counter
    station = load_station(args.station)
    steps = max(TETHER_EPISODE_STEPS, args.steps)
    print(f"station {station.name}: {station.n_anchors} anchors, {station.n_robots} robots, {station.substeps} "
          f"substeps per env step, {steps} steps x {args.repeats} repeats (median), {args.clock} clock; "
          f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores\n")
    tether_table(station, steps, args.repeats, args.reference, args.clock)


if __name__ == "__main__":
    main()
