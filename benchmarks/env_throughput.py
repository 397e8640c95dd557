"""Environment throughput: env-steps/s of the transport envs against a reference commit.

First table: the transport Gymnasium env (dense and sparse reward) and PettingZoo env of this tree, of this tree
on its pure-Python path (``IMPACT_ENV_PURE_PYTHON=1``) and of a reference commit (``--ref``, default 0378a64,
exported with ``git archive``: :mod:`benchmarks.git_tree`), each in a fresh process, the three taking turns in
every repeat; and the bare pymunk loop with the same bodies and substeps (set forces, step, read bodies), the
floor of the public API. Second table: the STL monitor's update on the scenario's task, per step, fed one
recorded episode (the reference as its env calls it, with the positions dict; this tree as its env calls it,
with the state array), and whether both trees give the same values. Third: whether an episode of each env
(random actions, seed 0) is the same bit for bit in both trees (observations, rewards, infos). The tether
envs have their own table: :mod:`benchmarks.tether_throughput`. This module imports the packages only inside
its functions, so that the reference tree's process can run them. Usage:

    python -m benchmarks.env_throughput [--scenario corridor] [--steps 20000] [--repeats 3]
                                        [--ref 0378a64 | --ref ""] [--wall]

Every rate is steps per second of the process's CPU time (``--wall``: of the wall clock): on a shared machine the
other jobs' share of the cores then does not enter, and each loop is one thread.
"""

from __future__ import annotations

import argparse
import hashlib
import math
import os
import statistics
import time

import numpy as np

from benchmarks.git_tree import ROOT, export_tree, run_in_tree

# "cpu": the process's CPU time (time.process_time), so that the other jobs of a shared machine do not enter a
# loop's rate (every loop here is one thread); "wall": time.perf_counter
CLOCKS = {"cpu": time.process_time, "wall": time.perf_counter}

def _transport_api():
    """(TransportEnv, TransportParallelEnv, World, load_scenario) of the tree on the path: this layout, or the
    one before 0.3.0 (``impact_env.envs``, ``impact_env.physics``; the reference commit's)."""
    try:
        from impact_env.transport.gym_env import TransportEnv
        from impact_env.transport.pettingzoo_env import TransportParallelEnv
        from impact_env.transport.physics import World
        from impact_env.transport.scenario import load_scenario
    except ImportError:
        from impact_env.envs import TransportEnv, TransportParallelEnv
        from impact_env.physics import World
        from impact_env.scenario import load_scenario
    return TransportEnv, TransportParallelEnv, World, load_scenario


def _actions(n_robots: int) -> np.ndarray:
    return np.random.default_rng(0).uniform(-1, 1, (1000, 3 * n_robots)).astype(np.float32)


def bare_pymunk(scenario_name: str, steps: int, clock: str = "cpu") -> float:
    """Steps/s of the pymunk loop alone: body forces, substeps, read every body's state (public API)."""
    _, _, World, load_scenario = _transport_api()
    scenario = load_scenario(scenario_name)
    actions = _actions(len(scenario.robots))
    world = World(scenario)
    space, robots, bodies = world.space, world.robots, world.bodies
    dt, substeps = world.dt_s, world.substeps
    limits = np.array([[*r.thrust_limit_N, r.torque_limit_Nm] for r in scenario.robots])
    wrenches = [[tuple(w) for w in (a.reshape(len(robots), 3) * limits)] for a in actions]
    now = CLOCKS[clock]
    start = now()
    for k in range(steps):
        w = wrenches[k % len(wrenches)]
        for _ in range(substeps):
            for body, (fx, fy, tau) in zip(robots, w):
                body.apply_force_at_local_point((fx, fy))
                body.torque = tau
            space.step(dt)
        [(b.position, b.velocity, b.angle, b.angular_velocity) for b in bodies]
    return steps / (now() - start)


def gym_env(scenario_name: str, steps: int, reward_mode: str, clock: str = "cpu") -> float:
    TransportEnv, _, _, load_scenario = _transport_api()
    scenario = load_scenario(scenario_name)
    actions = _actions(len(scenario.robots))
    env = TransportEnv(scenario, reward_mode=reward_mode)
    env.reset(seed=0)
    now = CLOCKS[clock]
    start = now()
    for k in range(steps):
        _, _, terminated, truncated, _ = env.step(actions[k % len(actions)])
        if terminated or truncated:
            env.reset()
    return steps / (now() - start)


def pettingzoo_env(scenario_name: str, steps: int, clock: str = "cpu") -> float:
    _, TransportParallelEnv, _, load_scenario = _transport_api()
    scenario = load_scenario(scenario_name)
    actions = _actions(len(scenario.robots))
    env = TransportParallelEnv(scenario)
    env.reset(seed=0)
    agents = env.possible_agents
    joint = [{a: act[3 * i: 3 * i + 3] for i, a in enumerate(agents)} for act in actions]
    now = CLOCKS[clock]
    start = now()
    for k in range(steps):
        env.step(joint[k % len(joint)])
        if not env.agents:
            env.reset()
    return steps / (now() - start)


ENV_LOOPS = ("Gymnasium env, dense reward", "Gymnasium env, sparse reward", "PettingZoo parallel env, dense reward")


def transport_rates(scenario_name: str, steps: int, clock: str = "cpu") -> list[float]:
    """Steps/s of the ENV_LOOPS, in their order, in this process."""
    return [gym_env(scenario_name, steps, "dense", clock), gym_env(scenario_name, steps, "sparse", clock),
            pettingzoo_env(scenario_name, steps, clock)]


def stl_trace(scenario_name: str, steps: int) -> np.ndarray:
    """Body positions (steps + 1, n_bodies, 2) of the Gym env under the benchmark's random actions (reset first)."""
    TransportEnv, _, _, load_scenario = _transport_api()
    scenario = load_scenario(scenario_name)
    actions = _actions(len(scenario.robots))
    env = TransportEnv(scenario)
    obs, _ = env.reset(seed=0)
    out = []
    for k in range(steps + 1):
        out.append([s[:2] for s in env.unwrapped.core._state])
        if k < steps:
            env.step(actions[k % len(actions)])
    return np.array(out)


def stl_update_cost(scenario_name: str, trace: np.ndarray, repeats: int,
                    clock: str = "cpu") -> tuple[float, list[float]]:
    """(us per update, median of ``repeats`` passes; the values) of the task's monitor fed ``trace`` as the env of
    the tree on the path feeds it: the compiled monitor on the state array where the tree has one, else
    OnlineMonitor on a positions dict (built before the clock starts)."""
    _, _, _, load_scenario = _transport_api()
    from impact_env.stl import OnlineMonitor

    scenario = load_scenario(scenario_name)
    names = [b.name for b in scenario.bodies]
    regions, dt = scenario.region_map(), scenario.control_period_s
    try:
        from impact_env.stl.compiled import compiled_monitor
        monitor = compiled_monitor(scenario.formula, regions, dt, names)
    except ImportError:
        monitor = None
    if monitor is not None:
        samples = []
        for xy in trace:
            state = np.zeros((len(names), 6))
            state[:, :2] = xy
            samples.append(state)
        update = monitor.update_rows
    else:
        monitor = OnlineMonitor(scenario.formula, regions, dt)
        samples = [{n: (float(x), float(y)) for n, (x, y) in zip(names, xy)} for xy in trace]
        update = monitor.update
    costs, now = [], CLOCKS[clock]
    for _ in range(repeats):
        monitor.reset()
        start = now()
        values = [update(sample) for sample in samples]
        costs.append((now() - start) / len(samples) * 1e6)
    return statistics.median(costs), values


def episode_digest(scenario_name: str, steps: int) -> tuple[str, str]:
    """sha256 of what the Gym env and the PettingZoo env return over ``steps`` steps (random actions, seed 0,
    reset at the horizon): observations' bytes, rewards, flags and infos."""
    TransportEnv, TransportParallelEnv, _, load_scenario = _transport_api()
    scenario = load_scenario(scenario_name)
    actions = _actions(len(scenario.robots))
    gym_hash = hashlib.sha256()
    env = TransportEnv(scenario)
    obs, info = env.reset(seed=0)
    gym_hash.update(obs.tobytes() + repr(sorted(info.items())).encode())
    for k in range(steps):
        obs, reward, terminated, truncated, info = env.step(actions[k % len(actions)])
        gym_hash.update(obs.tobytes() + repr((reward, terminated, truncated, sorted(info.items()))).encode())
        if terminated or truncated:
            obs, info = env.reset()
            gym_hash.update(obs.tobytes() + repr(sorted(info.items())).encode())
    pz_hash = hashlib.sha256()
    env = TransportParallelEnv(scenario)
    agents = env.possible_agents
    observations, infos = env.reset(seed=0)
    for k in range(steps):
        act = actions[k % len(actions)]
        observations, rewards, terms, truncs, infos = env.step({a: act[3 * i: 3 * i + 3] for i, a in enumerate(agents)})
        for a in sorted(observations):
            pz_hash.update(observations[a].tobytes())
        pz_hash.update(repr((sorted(rewards.items()), sorted(terms.items()), sorted(truncs.items()),
                             sorted((a, sorted(i.items())) for a, i in infos.items()))).encode())
        if not env.agents:
            observations, infos = env.reset()
    return gym_hash.hexdigest(), pz_hash.hexdigest()


def _table(cases, repeats: int) -> None:
    print("| loop | env-steps/s | us/step | vs bare pymunk |")
    print("|---|---:|---:|---:|")
    base = None
    for label, fn in cases:
        rate = statistics.median(fn() for _ in range(repeats))
        base = base or rate
        print(f"| {label} | {rate:,.0f} | {1e6 / rate:.1f} | {rate / base:.2f} |", flush=True)


def _pure_python(function: str, *args):
    """``function(*args)`` in a fresh process of this tree on its pure-Python path."""
    os.environ["IMPACT_ENV_PURE_PYTHON"] = "1"
    try:
        return run_in_tree(ROOT, function, *args)
    finally:
        del os.environ["IMPACT_ENV_PURE_PYTHON"]


def transport_tables(scenario_name: str, steps: int, repeats: int, ref: str, clock: str = "cpu") -> None:
    """The transport tables: this tree (compiled and pure Python) against ``ref`` (none if empty)."""
    from impact_env.transport.scenario import load_scenario

    scenario = load_scenario(scenario_name)
    tree = export_tree(ref, prefix="impact_env_throughput_") if ref else None
    runs = {"this": [], "pure": [], "ref": []}
    for r in range(repeats):  # the trees take turns, so that a change of load falls on all of them
        order = ["this", "pure", "ref"] if r % 2 == 0 else ["ref", "pure", "this"]
        for who in order:
            if who == "this":
                runs[who].append(run_in_tree(ROOT, "benchmarks.env_throughput:transport_rates", scenario_name, steps,
                                               clock))
            elif who == "pure":
                runs[who].append(_pure_python("benchmarks.env_throughput:transport_rates", scenario_name, steps,
                                               clock))
            elif tree:
                runs[who].append(run_in_tree(tree, "benchmarks.env_throughput:transport_rates", scenario_name, steps,
                                               clock))
    bare = statistics.median(run_in_tree(ROOT, "benchmarks.env_throughput:bare_pymunk", scenario_name, steps, clock)
                             for _ in range(repeats))
    med = {who: [statistics.median(col) for col in zip(*rows)] for who, rows in runs.items() if rows}
    ref_label = ref or "-"
    print(f"scenario {scenario.name}: {len(scenario.bodies)} bodies, {scenario.substeps} substeps per env step, "
          f"{steps} steps x {repeats} repeats (median), each tree in its own process, {clock} time\n")
    print(f"| loop | {ref_label} env-steps/s | this tree, pure Python | this tree | this tree vs {ref_label} "
          "| vs bare pymunk |")
    print("|---|---:|---:|---:|---:|---:|")
    for i, label in enumerate(ENV_LOOPS):
        this, pure = med["this"][i], med["pure"][i]
        old = med["ref"][i] if "ref" in med else math.nan
        print(f"| {label} | {old:,.0f} | {pure:,.0f} | {this:,.0f} | {this / old:.2f}x | {this / bare:.2f} |")
    print(f"| bare pymunk loop (same bodies, substeps; public API) | | | {bare:,.0f} | | 1.00 |")
    gym, pz = med["this"][0], med["this"][2]
    print(f"\nPettingZoo / Gymnasium (dense), this tree: {pz / gym:.2f}"
          + (f"; {ref_label}: {med['ref'][2] / med['ref'][0]:.2f}" if "ref" in med else ""))

    trace = stl_trace(scenario_name, 1000)
    print(f"\nSTL monitor update on {scenario.name}'s task, one recorded episode of {len(trace)} samples, median of "
          f"{max(5, repeats)} passes:\n")
    print(f"| tree | us/update | vs {ref_label} |\n|---|---:|---:|")
    this_cost, this_values = run_in_tree(ROOT, "benchmarks.env_throughput:stl_update_cost", scenario_name, trace,
                                         max(5, repeats), clock)
    pure_cost, pure_values = _pure_python("benchmarks.env_throughput:stl_update_cost", scenario_name, trace,
                                          max(5, repeats), clock)
    if tree:
        ref_cost, ref_values = run_in_tree(tree, "benchmarks.env_throughput:stl_update_cost", scenario_name, trace,
                                           max(5, repeats), clock)
        print(f"| {ref_label} (OnlineMonitor, positions dict) | {ref_cost:.2f} | 1.00 |")
    else:
        ref_cost, ref_values = math.nan, this_values
    print(f"| this tree, pure Python (OnlineMonitor) | {pure_cost:.2f} | {pure_cost / ref_cost:.2f} |")
    print(f"| this tree (compiled monitor, state array) | {this_cost:.2f} | {this_cost / ref_cost:.2f} |")
    same = this_values == ref_values == pure_values
    print(f"\nmonitor values of the three identical to the last bit: {'yes' if same else 'NO'}")

    digests = {"this": run_in_tree(ROOT, "benchmarks.env_throughput:episode_digest", scenario_name, 2000),
               "pure": _pure_python("benchmarks.env_throughput:episode_digest", scenario_name, 2000)}
    if tree:
        digests["ref"] = run_in_tree(tree, "benchmarks.env_throughput:episode_digest", scenario_name, 2000)
    print("\n2,000 steps of each env, random actions, seed 0 (sha256 of observations, rewards, flags, infos):\n")
    print("| env | " + " | ".join({"this": "this tree", "pure": "pure Python", "ref": ref_label}[k] for k in digests)
          + " | identical |")
    print("|---|" + "---|" * len(digests) + "---|")
    for i, label in enumerate(("Gymnasium", "PettingZoo")):
        values = [d[i] for d in digests.values()]
        print(f"| {label} | " + " | ".join(v[:12] for v in values) + f" | {'yes' if len(set(values)) == 1 else 'NO'} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenario", default="corridor")
    parser.add_argument("--steps", type=int, default=20000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--ref", default="0378a64", help="reference commit of the transport table ('' for none)")
    parser.add_argument("--wall", action="store_true", help="time by the wall clock, not the processes' CPU time")
    args = parser.parse_args()
    clock = "wall" if args.wall else "cpu"
    transport_tables(args.scenario, args.steps, args.repeats, args.ref, clock)


if __name__ == "__main__":
    main()
