"""PPO against the tether expert on the stations (``python -m baselines.tether_ppo``).

python -m baselines.tether_ppo: PPO on every shipped station with the hold task, seeds 0..2, trained in chunks
that each end in a saved model (so a killed run resumes from its last chunk), then PPO and the expert flown on
the same seeded episodes; one cell per (station, controller, seed) in results/tether_baselines/cells.jsonl,
written atomically (impact_env.results_store), and the table with intervals in table.md.
"""

from __future__ import annotations

from typing import Any

RESULTS = "results/tether_baselines"
RUNS = "runs/tether_baselines"


def _cell_key(cell: dict) -> tuple:
    return (cell["station"], cell["controller"], cell["seed"])


def train_station(station: str, seed: int, timesteps: int, chunk: int, runs: str, env_options: dict[str, Any]
                  ) -> dict[str, Any]:
    """Train (or continue) PPO on one station up to ``timesteps`` env steps, ``chunk`` at a time; one process,
    one torch thread, one in-process env. Returns the run's train.json."""
    import json
    from pathlib import Path

    import torch

    from baselines.train import TrainConfig, train

    torch.set_num_threads(1)
    out = Path(runs) / f"ppo_{station}_s{seed}"
    done = json.loads((out / "train.json").read_text()).get("timesteps_trained", 0) \
        if (out / "train.json").is_file() and (out / "model.zip").is_file() else 0
    while done < timesteps:
        target = min(timesteps, done + chunk)
        train(TrainConfig(algo="ppo", scenario=station, timesteps=target, seed=seed, n_envs=1, out=str(out),
                          env_options=dict(env_options), progress_bar=False, resume=done > 0,
                          eval_freq=max(chunk, 50_000)))
        done = json.loads((out / "train.json").read_text())["timesteps_trained"]
    return json.loads((out / "train.json").read_text())


def fly(job: tuple[str, str, int, int, str, dict]) -> dict[str, Any]:
    """One cell: ``episodes`` seeded episodes of one controller (``expert`` or ``ppo``) on one station (a sweep job)."""
    import time
    from pathlib import Path

    import numpy as np

    from impact_env.controllers import make_controller
    from impact_env.rollout import run_episode
    from impact_env.tether.gym_env import TetherEnv

    station, controller, seed, episodes, runs, env_options = job
    env = TetherEnv(station, **env_options)
    spec = "expert" if controller == "expert" else str(Path(runs) / f"ppo_{station}_s{seed}" / "model.zip")
    agent = make_controller(spec, env.station)
    start = time.perf_counter()
    out = []
    for k in range(episodes):
        res = run_episode(env, agent, seed=1_000_000 + 1000 * seed + k)
        info = res.final_info
        assert info is not None  # run_episode ran at least one step
        out.append({"seed": 1_000_000 + 1000 * seed + k, "success": bool(res.success), "robustness": res.robustness,
                    "time_to_goal_s": info["time_to_goal_s"], "time_at_rest_in_goal_s": info["time_at_rest_in_goal_s"],
                    "final_speed_mps": info["speed_mps"], "winch_work_J": info["winch_work_J"],
                    "switches": info["switches"]})
    env.close()
    return {"station": station, "controller": controller, "seed": seed, "episodes": out,
            "success_rate": float(np.mean([e["success"] for e in out])), "wall_s": time.perf_counter() - start}


def _wilson(successes: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """The Wilson score interval of a success rate (95 % by default)."""
    if n == 0:
        return (0.0, 1.0)
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * ((p * (1 - p) / n + z * z / (4 * n * n)) ** 0.5) / (1 + z * z / n)
    return (max(0.0, centre - half), min(1.0, centre + half))


def table(cells: list[dict], trained: dict[tuple, dict]) -> str:
    """The markdown table: per station and controller, success over all seeds' episodes (Wilson 95 %), the
    spread of the per-seed success rates, robustness, time to goal and hold; and the PPO runs' budgets."""
    import numpy as np

    rows = ["| station | controller | seeds | episodes | success (95 % interval) | per-seed success | "
            "robustness m, mean +- sd | time to goal s (reached) | held at rest s, mean |",
            "|---|---|---:|---:|---|---|---|---|---:|"]
    for station in sorted({c["station"] for c in cells}):
        for controller in ("expert", "ppo"):
            mine = [c for c in cells if c["station"] == station and c["controller"] == controller]
            if not mine:
                continue
            eps = [e for c in sorted(mine, key=lambda c: c["seed"]) for e in c["episodes"]]
            wins = sum(e["success"] for e in eps)
            lo, hi = _wilson(wins, len(eps))
            rho = np.array([e["robustness"] for e in eps])
            reached = [e["time_to_goal_s"] for e in eps if e["time_to_goal_s"] is not None]
            goal = f"{np.mean(reached):.0f} ({len(reached)}/{len(eps)})" if reached else f"- (0/{len(eps)})"
            per_seed = " / ".join(f"{100 * c['success_rate']:.0f} %" for c in sorted(mine, key=lambda c: c["seed"]))
            rows.append(f"| {station} | {controller} | {len(mine)} | {len(eps)} | {100 * wins / len(eps):.0f} % "
                        f"({100 * lo:.0f}-{100 * hi:.0f} %) | {per_seed} | {rho.mean():+.2f} +- {rho.std():.2f} | "
                        f"{goal} | {np.mean([e['time_at_rest_in_goal_s'] for e in eps]):.0f} |")
    if trained:
        rows += ["", "| PPO run | env steps | wall clock s |", "|---|---:|---:|"]
        for (station, seed), meta in sorted(trained.items()):
            rows.append(f"| {station}, seed {seed} | {meta['timesteps_trained']:,} | {meta['wall_time_s']:.0f} |")
    return "\n".join(rows) + "\n"


def main(argv: list[str] | None = None) -> None:
    """PPO against the expert on tether stations (see the comment above :func:`train_station`)."""
    import argparse
    import json
    import os
    from pathlib import Path

    from impact_env.results_store import CellStore, write_atomic
    from impact_env.sweep import add_engine_arguments, engine_config, open_engine
    from impact_env.tether.station import station_names

    p = argparse.ArgumentParser(prog="python -m baselines.tether_ppo", description=main.__doc__)
    p.add_argument("--stations", default=",".join(station_names()))
    p.add_argument("--seeds", default="0,1,2")
    p.add_argument("--timesteps", type=int, default=300_000, help="env steps per PPO run")
    p.add_argument("--chunk", type=int, default=50_000, help="env steps between saved models (what a kill loses)")
    p.add_argument("--episodes", type=int, default=20, help="episodes per (station, controller, seed) cell")
    p.add_argument("--fidelity", default="kinematic")
    p.add_argument("--initial-position-noise-m", type=float, default=0.3)
    p.add_argument("--phase", default="all", choices=("train", "fly", "all"))
    p.add_argument("--out", default=RESULTS)
    p.add_argument("--runs", default=RUNS)
    add_engine_arguments(p, default_workers=min(2, os.cpu_count() or 1))
    args = p.parse_args(argv)

    stations, seeds = args.stations.split(","), [int(s) for s in args.seeds.split(",")]
    options = {"fidelity": args.fidelity, "initial_position_noise_m": args.initial_position_noise_m}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    trained: dict[tuple, dict] = {}
    with open_engine(engine_config(args)) as engine:
        if args.phase in ("train", "all"):
            train_jobs = [(st, seed, args.timesteps, args.chunk, args.runs, options)
                          for st in stations for seed in seeds]
            for job, meta in zip(train_jobs, engine.map(_train_job, train_jobs)):
                trained[(job[0], job[1])] = meta
                print(f"trained {job[0]} seed {job[1]}: {meta['timesteps_trained']:,} steps, "
                      f"{meta['wall_time_s']:.0f} s", flush=True)
            runs_done = json.loads((out / "training.json").read_text()) if (out / "training.json").is_file() else {}
            runs_done.update({f"{k[0]}/s{k[1]}": v for k, v in trained.items()})  # other stations' runs kept
            write_atomic(out / "training.json", json.dumps(runs_done, indent=1))
            trained = {(k.split("/s")[0], int(k.split("/s")[1])): v for k, v in runs_done.items()}
        if args.phase in ("fly", "all"):
            store = CellStore(out / "cells.jsonl", key=_cell_key)
            fly_jobs = [(st, c, seed, args.episodes, args.runs, options) for st in stations for c in ("expert", "ppo")
                        for seed in seeds if (st, c, seed) not in store]
            for cell in engine.map(fly, fly_jobs):
                store.put(cell)
                print(f"{cell['station']} {cell['controller']} seed {cell['seed']}: "
                      f"{100 * cell['success_rate']:.0f} %", flush=True)
            if (out / "training.json").is_file() and not trained:
                raw = json.loads((out / "training.json").read_text())
                trained = {(k.split("/s")[0], int(k.split("/s")[1])): v for k, v in raw.items()}
            text = table(store.cells(), trained)
            write_atomic(out / "table.md", text)
            print(text)


def _train_job(job: tuple) -> dict[str, Any]:
    return train_station(*job)


if __name__ == "__main__":
    main()
