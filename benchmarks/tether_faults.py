"""Tether faults benchmark: the expert against the thesis pipeline's plan flown open loop, fault by fault.

Per shipped station and fault, ``--seeds`` seeded episodes (default 50) of the hold task (``TetherEnv`` v1,
``--fidelity`` kinematic by default, the thesis's model) with one fault drawn from the episode's seed
(:mod:`impact_env.tether.faults`, times uniform in 10-150 s):

- ``anchor``: one anchor fails (the one a tether pulls on then, else the next one attached: it refuses);
- ``snap``: one tether snaps;
- ``dropout``: one robot drops out;
- ``winch``: every winch off its speed by 10-30 % (random sign per robot);
- ``none``: no fault, the reference.

Controllers: ``expert`` (the tether expert, closed loop: it excludes a failed anchor and plans again from where
the cargo is) and ``open_loop`` (the thesis's divide and conquer with z3 under the line-of-sight rule, its pulls
flown by the clock: each robot attaches ``t_switch`` before its pull starts, pulls for the pull's length over
``w`` and lets go; no feedback, as the thesis's pipeline would command it). The z3 plans are made once per
station and cached in ``--out``/plans/. A cell is (station, fault, controller) with its episodes (success,
time to goal, time at rest in the goal, final speed, attachments), one line of ``--out``/cells.jsonl written
atomically, so an interrupted run resumes. Prints the table (success rate with a 95 % Wilson interval, the mean
time to goal of the episodes that reached it) and writes it to ``--out``/table.md. From the repository root:

    python -m benchmarks.tether_faults [--stations L,T] [--faults anchor,snap] [--seeds 50] [--workers 2]
                                       [--fidelity kinematic] [--z3-timeout 20] [--table-only]
"""

from __future__ import annotations

import argparse
import math
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks import open_engine
from impact_env.results_store import CellStore, write_atomic
from impact_env.sweep import add_engine_arguments, engine_config

RESULTS = Path(__file__).resolve().parents[1] / "results" / "tether_faults"
FAULTS = {"none": None, "anchor": {"anchor_failures": 1}, "snap": {"tether_snaps": 1},
          "dropout": {"robot_dropouts": 1}, "winch": {"winch_speed_error": (0.1, 0.3)}}
CONTROLLERS = ("expert", "open_loop")


class OpenLoopPlan:
    """A tether plan flown by the clock (no feedback), as ``TetherPlan.travel_time_s`` times it with two robots:
    pull ``i``'s robot (the two take turns) attaches ``t_switch`` before pull ``i - 1`` ends, or as soon as it
    has let go of its previous pull if that is later (the cargo then waits); each robot lets go when its pull
    has run its length at ``w``. Commands fall on the control steps nearest those times."""

    name = "open_loop"

    def __init__(self, station: Any, plan: Any) -> None:
        self.station, self.plan = station, plan
        dt, t_switch, w = station.control_period_s, station.switch_time_s, plan.pull_speed_mps
        robots = min(2, station.n_robots)
        self.schedule: dict[int, list[tuple[int, int]]] = {}  # step -> [(robot, command)]
        ends: list[float] = []
        for i, p in enumerate(plan.pulls):
            previous_end = ends[i - 1] if i >= 1 else t_switch
            robot_free = ends[i - robots] if i >= robots else 0.0
            attach = max(previous_end - t_switch, robot_free) if i else 0.0
            start = max(previous_end, attach + t_switch)
            ends.append(start + p.length_m / w)
            robot = i % robots
            self.schedule.setdefault(round(attach / dt), []).append((robot, 2 + p.anchor))
            self.schedule.setdefault(round(ends[-1] / dt), []).append((robot, 1))
        self.n_robots = station.n_robots

    def reset(self, env: Any = None, seed: int | None = None) -> None:
        self.step = 0

    def act(self, observation: np.ndarray, info: dict | None = None) -> np.ndarray:
        commands = [0] * self.n_robots
        for robot, command in self.schedule.get(self.step, []):
            # a release and an attach of one robot in one step: the attach (it lets go of the old anchor first)
            if command >= 2 or commands[robot] == 0:
                commands[robot] = command
        self.step += 1
        return np.asarray(commands, dtype=np.int64)


def thesis_plan(station_name: str, out: Path, z3_timeout_s: float):
    """The thesis pipeline's plan for a station (line-of-sight rule), cached as ``out/plans/<station>.json``."""
    from impact_env.tether.station import load_station
    from planners.tether.plan import TetherPlan
    from planners.tether.smt import SmtConfig, plan_smt

    path = out / "plans" / f"{station_name}.json"
    station = load_station(station_name)
    if path.is_file():
        return TetherPlan.load(path)
    plan = plan_smt(station, SmtConfig(rule="line_of_sight", timeout_s=z3_timeout_s))
    plan.check(station)
    path.parent.mkdir(parents=True, exist_ok=True)
    plan.save(path)
    return plan


def run_cell(job: tuple[str, str, str, int, str, str]) -> dict[str, Any]:
    """One cell (a sweep job): ``seeds`` episodes of one controller on one station under one fault."""
    from impact_env.rollout import run_episode
    from impact_env.tether.gym_env import TetherEnv
    from impact_env.tether.station import load_station
    from planners.tether.expert import TetherExpert
    from planners.tether.plan import TetherPlan

    station_name, fault, controller, seeds, fidelity, plan_path = job
    station = load_station(station_name)
    env = TetherEnv(station, fidelity=fidelity, faults=FAULTS[fault])
    agent = TetherExpert(station) if controller == "expert" else OpenLoopPlan(station, TetherPlan.load(plan_path))
    start = time.perf_counter()
    episodes = []
    for seed in range(seeds):
        res = run_episode(env, agent, seed=seed)
        info = res.final_info
        episodes.append({"seed": seed, "success": bool(res.success), "robustness": res.robustness,
                         "time_to_goal_s": info["time_to_goal_s"],
                         "time_at_rest_in_goal_s": info["time_at_rest_in_goal_s"],
                         "final_speed_mps": info["speed_mps"], "switches": info["switches"],
                         "failed_anchors": info["failed_anchors"], "dropped_robots": info["dropped_robots"]})
    env.close()
    return {"station": station_name, "fault": fault, "controller": controller, "fidelity": fidelity,
            "seeds": seeds, "episodes": episodes, "wall_s": time.perf_counter() - start}


def wilson(successes: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """The 95 % Wilson score interval of a success rate."""
    if n == 0:
        return (0.0, 1.0)
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return (max(0.0, centre - half), min(1.0, centre + half))


def summary(cell: dict) -> str:
    eps = cell["episodes"]
    wins = sum(e["success"] for e in eps)
    lo, hi = wilson(wins, len(eps))
    reached = [e["time_to_goal_s"] for e in eps if e["time_to_goal_s"] is not None]
    goal = f"{np.mean(reached):.0f} s" if reached else "-"
    return f"{wins}/{len(eps)} ({100 * lo:.0f}-{100 * hi:.0f} %), {goal}"


def table(cells: list[dict], stations: list[str], faults: list[str]) -> str:
    by = {(c["station"], c["fault"], c["controller"]): c for c in cells}
    head = "| station | controller | " + " | ".join(faults) + " |"
    rows = [head, "|---|---|" + "---|" * len(faults)]
    for st in stations:
        for controller in CONTROLLERS:
            cells_ = [by.get((st, f, controller)) for f in faults]
            if not any(cells_):
                continue
            rows.append(f"| {st} | {controller} | " + " | ".join(summary(c) if c else "not run" for c in cells_) + " |")
    return "\n".join(rows) + "\n"


def main() -> None:
    from impact_env.tether.station import station_names

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--stations", default=",".join(station_names()))
    parser.add_argument("--faults", default=",".join(FAULTS))
    parser.add_argument("--controllers", default=",".join(CONTROLLERS))
    parser.add_argument("--seeds", type=int, default=50)
    parser.add_argument("--fidelity", default="kinematic")
    parser.add_argument("--z3-timeout", type=float, default=20.0, help="z3's limit per check (s)")
    parser.add_argument("--out", default=str(RESULTS))
    parser.add_argument("--table-only", action="store_true", help="print and write the table of the cells done")
    add_engine_arguments(parser, default_workers=min(2, os.cpu_count() or 1))
    args = parser.parse_args()
    out = Path(args.out)
    stations, faults = args.stations.split(","), args.faults.split(",")
    for f in faults:
        if f not in FAULTS:
            parser.error(f"unknown fault {f!r}; faults: {', '.join(FAULTS)}")
    store = CellStore(out / "cells.jsonl", key=lambda c: (c["station"], c["fault"], c["controller"], c["fidelity"]))
    if not args.table_only:
        controllers = args.controllers.split(",")
        plans = {}
        if "open_loop" in controllers:
            for st in stations:
                t0 = time.perf_counter()
                plan = thesis_plan(st, out, args.z3_timeout)
                plans[st] = str(out / "plans" / f"{st}.json")
                print(f"thesis pipeline plan for {st}: {plan.switches} pulls ({time.perf_counter() - t0:.1f} s)",
                      flush=True)
        jobs = [(st, f, c, args.seeds, args.fidelity, plans.get(st, "")) for st in stations for f in faults
                for c in controllers if (st, f, c, args.fidelity) not in store]
        print(f"{len(jobs)} cells to run ({len(store)} done)", flush=True)
        with open_engine(engine_config(args)) as engine:
            for cell in engine.map(run_cell, jobs):
                store.put(cell)
                print(f"{cell['station']} {cell['fault']} {cell['controller']}: {summary(cell)} "
                      f"({cell['wall_s']:.0f} s)", flush=True)
    cells = [c for c in store.cells() if c["fidelity"] == args.fidelity]
    text = (f"Faults benchmark, {args.fidelity} fidelity, the hold task; per cell: successes/episodes (95 % "
            "Wilson interval), mean time to goal of those that reached it\n\n" + table(cells, stations, faults))
    write_atomic(out / f"table_{args.fidelity}.md", text)
    print(text)


if __name__ == "__main__":
    main()
