"""Environment throughput: env-steps/s of the Gymnasium env, the PettingZoo env and a bare pymunk loop.

All three simulate the same scenario with the same bodies and substeps, one process, one core, in the same
run; the bare loop is the floor (physics only: set forces, step, read bodies). Prints a markdown table with
each row's ratio to the bare loop. Usage:

    python benchmarks/env_throughput.py [--scenario corridor] [--steps 20000] [--repeats 3]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

import impact_env  # noqa: F401  (registers the environments)
from impact_env.envs.transport import TransportEnv
from impact_env.envs.transport_parallel import TransportParallelEnv
from impact_env.physics import World
from impact_env.scenario import load_scenario


def bare_pymunk(scenario, steps: int, actions: np.ndarray) -> float:
    """Steps/s of the pymunk loop alone: body forces, substeps, read every body's state."""
    world = World(scenario)
    space, robots, bodies = world.space, world.robots, world.bodies
    dt, substeps = world.dt_s, world.substeps
    limits = np.array([[*r.thrust_limit_N, r.torque_limit_Nm] for r in scenario.robots])
    wrenches = [[tuple(w) for w in (a.reshape(len(robots), 3) * limits)] for a in actions]
    start = time.perf_counter()
    for k in range(steps):
        w = wrenches[k % len(wrenches)]
        for _ in range(substeps):
            for body, (fx, fy, tau) in zip(robots, w):
                body.apply_force_at_local_point((fx, fy))
                body.torque = tau
            space.step(dt)
        [(b.position, b.velocity, b.angle, b.angular_velocity) for b in bodies]
    return steps / (time.perf_counter() - start)


def gym_env(scenario, steps: int, actions: np.ndarray, reward_mode: str) -> float:
    env = TransportEnv(scenario, reward_mode=reward_mode)
    env.reset(seed=0)
    start = time.perf_counter()
    for k in range(steps):
        _, _, terminated, truncated, _ = env.step(actions[k % len(actions)])
        if terminated or truncated:
            env.reset()
    return steps / (time.perf_counter() - start)


def pettingzoo_env(scenario, steps: int, actions: np.ndarray) -> float:
    env = TransportParallelEnv(scenario)
    env.reset(seed=0)
    agents = env.possible_agents
    joint = [{a: act[3 * i: 3 * i + 3] for i, a in enumerate(agents)} for act in actions]
    start = time.perf_counter()
    for k in range(steps):
        env.step(joint[k % len(joint)])
        if not env.agents:
            env.reset()
    return steps / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenario", default="corridor")
    parser.add_argument("--steps", type=int, default=20000)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    scenario = load_scenario(args.scenario)
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (1000, 3 * len(scenario.robots))).astype(np.float32)

    cases = [
        ("bare pymunk loop (same bodies, substeps)", lambda: bare_pymunk(scenario, args.steps, actions)),
        ("Gymnasium env, dense reward", lambda: gym_env(scenario, args.steps, actions, "dense")),
        ("Gymnasium env, sparse reward", lambda: gym_env(scenario, args.steps, actions, "sparse")),
        ("PettingZoo parallel env, dense reward", lambda: pettingzoo_env(scenario, args.steps, actions)),
    ]
    print(f"scenario {scenario.name}: {len(scenario.bodies)} bodies, {scenario.substeps} substeps per env step, "
          f"{args.steps} steps x {args.repeats} repeats (median)\n")
    print("| loop | env-steps/s | us/step | vs bare pymunk |")
    print("|---|---:|---:|---:|")
    base = None
    for label, fn in cases:
        rate = statistics.median(fn() for _ in range(args.repeats))
        base = base or rate
        print(f"| {label} | {rate:,.0f} | {1e6 / rate:.1f} | {rate / base:.2f} |", flush=True)


if __name__ == "__main__":
    main()
