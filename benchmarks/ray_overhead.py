"""What Ray costs and buys on one machine: the same bench on local processes and on Ray, and sampling speed.

Table 1, sweeps: the episodes of ``impact-env bench`` (``baselines.bench._episode``, the same jobs, the same
seeds) on throw_and_catch_exp with 5 % thrust noise and 5 cm start noise, run in this process one at a time
(the baseline), on ``--workers`` local spawned processes, and as Ray tasks on a private local Ray instance with
as many CPUs, twice: the first Ray engine of the process starts the instance, every later one reuses it
(``EngineConfig.keep_ray``), so a "reused" start-up is what every Ray sweep after the first in a process costs
(before 0.3.0 each one paid a "started" row's). Two workloads: ``zero`` and ``random`` controllers (a 200-step
episode costs ~0.1 s, so the per-job overhead shows) and the ``expert`` (replanning and MPC: ~2-4 s per
episode). Episodes/s counts the sweep alone; starting the pool or Ray (and the first job's imports) is the
start-up column. Every engine's
results are compared with the baseline's, field by field ("same results").

Table 2, sampling env steps/s with the policy in the loop (a 128x128 tanh MLP per policy, observation
normalisation on, as in training): RLlib's PPO on the PettingZoo env (independent policies, one per robot) with
1 and 2 env runners (``synchronous_parallel_sample``: what one training iteration's sampling does), against
stable-baselines3's PPO on the central Gymnasium env with SubprocVecEnv of 1 and 2 envs (the rollout phase of
``learn``, timed by a callback). An env step moves both robots in both cases. The in-process random-action step
rate of each env is the ceiling. The load average is printed: the machine is shared, so compare rows of one
run. Usage:

    python -m benchmarks.ray_overhead [--episodes 100] [--expert-episodes 20] [--workers 2] [--steps 4096]
                                      [--skip-sweeps | --skip-sampling]
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

NOISE = {"thrust_noise": 0.05, "initial_position_noise_m": 0.05}
SCENARIO = "throw_and_catch_exp"


def _load() -> str:
    return " ".join(f"{x:.1f}" for x in os.getloadavg())


def _jobs(controllers: list[str], episodes: int, plan_handle=None) -> list:
    from baselines.bench import ControllerSpec

    return [(SCENARIO, ControllerSpec(c, c), seed, plan_handle if c == "expert" else None, dict(NOISE))
            for c in controllers for seed in range(episodes)]


def _key(r: dict) -> tuple:
    return (r["controller"], r["seed"], r["success"], r["robustness"], r["fuel_Ns"], r["impacts"])


def sweep_rows(controllers: list[str], episodes: int, workers: int, plan_path: str) -> list[str]:
    from baselines import bench
    from impact_env.sweep import EngineConfig, open_engine

    n = len(controllers) * episodes
    rows = []
    t0 = time.perf_counter()
    jobs = _jobs(controllers, episodes, plan_path)
    baseline = [bench._episode(job) for job in jobs]
    wall = time.perf_counter() - t0
    label = "+".join(controllers)
    rows.append(f"| {label} | this process, one at a time (baseline) | {n} | - | {wall:.1f} | {n / wall:.2f} | 1.00x | "
                f"- |")
    print(rows[-1], flush=True)
    from impact_env import sweep

    for name in ("local", "ray", "ray"):
        note = "" if name == "local" else ": reused, kept from before" if sweep._kept_ray else ": started for it"
        t0 = time.perf_counter()
        with open_engine(EngineConfig(name, workers=workers), n_jobs=n) as engine:
            handle = engine.share(plan_path)
            jobs = _jobs(controllers, episodes, handle)
            list(engine.map(bench._episode, jobs[:workers]))  # start-up: the first jobs import and compile
            started = time.perf_counter()
            results = list(engine.map(bench._episode, jobs))
            done = time.perf_counter()
            where = engine.describe() + note
        same = [_key(r) for r in results] == [_key(r) for r in baseline]
        rows.append(f"| {label} | {where} | {n} | {started - t0:.1f} | {done - started:.1f} | "
                    f"{n / (done - started):.2f} | {wall / (done - started):.2f}x | {'yes' if same else 'NO'} |")
        print(rows[-1], flush=True)
    return rows


def env_ceiling(steps: int) -> list[str]:
    """In-process env steps/s with random actions: the central Gymnasium env and the PettingZoo env."""
    from impact_env.transport.gym_env import TransportEnv
    from impact_env.transport.pettingzoo_env import parallel_env

    env = TransportEnv(SCENARIO, **NOISE)
    env.reset(seed=0)
    env.action_space.seed(0)
    t0 = time.perf_counter()
    for _ in range(steps):
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            env.reset()
    central = steps / (time.perf_counter() - t0)
    par = parallel_env(scenario=SCENARIO, **NOISE)
    par.reset(seed=0)
    t0 = time.perf_counter()
    for _ in range(steps):
        if not par.agents:
            par.reset()
        par.step({a: par.action_space(a).sample() for a in par.agents})
    pz = steps / (time.perf_counter() - t0)
    return [f"| ceiling: the central Gymnasium env, random actions, in this process | 1 | {central:,.0f} |",
            f"| ceiling: the PettingZoo env, random actions, in this process | 1 | {pz:,.0f} |"]


def rllib_sampling(env_runners: int, steps: int) -> str:
    import ray
    from ray.rllib.execution.rollout_ops import synchronous_parallel_sample

    from baselines import hyperparams
    from baselines.rllib_train import RLlibTrainConfig, build_algorithm, rllib_settings
    from impact_env.transport.scenario import load_scenario

    entry = hyperparams.load("ppo", "impact_env/ThrowAndCatchExp-v0")
    settings = rllib_settings(entry, 10**6)
    settings["train_batch_size_per_learner"] = steps
    ray.init(num_cpus=max(2, env_runners), include_dashboard=False, logging_level="ERROR")
    try:
        config = RLlibTrainConfig(SCENARIO, policies="independent", env_runners=env_runners, env_options=dict(NOISE))
        algo, _, _ = build_algorithm(config, settings, load_scenario(SCENARIO))
        group = algo.env_runner_group

        def sample() -> tuple[int, float]:
            t0 = time.perf_counter()
            episodes = synchronous_parallel_sample(worker_set=group, max_env_steps=steps, concat=True,
                                                   _uses_new_env_runners=True)
            return sum(e.env_steps() for e in episodes), time.perf_counter() - t0

        sample()  # warm-up: the runners build their envs and modules
        rates = [n / s for n, s in (sample() for _ in range(3))]
        algo.stop()
    finally:
        ray.shutdown()
    return (f"| RLlib PPO, PettingZoo env, {env_runners} env runner{'s' if env_runners > 1 else ''} | "
            f"{env_runners} | {np.median(rates):,.0f} |")


def sb3_sampling(n_envs: int, steps: int) -> str:
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import SubprocVecEnv, VecNormalize

    from impact_env.transport.gym_env import TransportEnv

    class RolloutTimer(BaseCallback):
        def __init__(self) -> None:
            super().__init__()
            self.seconds: list[float] = []

        def _on_rollout_start(self) -> None:
            self._t0 = time.perf_counter()

        def _on_rollout_end(self) -> None:
            self.seconds.append(time.perf_counter() - self._t0)

        def _on_step(self) -> bool:
            return True

    venv = VecNormalize(make_vec_env(TransportEnv, n_envs=n_envs, seed=0, vec_env_cls=SubprocVecEnv,
                                     env_kwargs={"scenario": SCENARIO, **NOISE}), gamma=0.999)
    per_env = steps // n_envs
    model = PPO("MlpPolicy", venv, n_steps=per_env, batch_size=min(256, per_env * n_envs), n_epochs=1, seed=0,
                policy_kwargs={"net_arch": [128, 128]}, verbose=0)
    timer = RolloutTimer()
    model.learn(total_timesteps=4 * per_env * n_envs, callback=timer)  # a warm-up rollout, then three
    venv.close()
    rates = [per_env * n_envs / s for s in timer.seconds[1:]]
    return f"| stable-baselines3 PPO, central env, SubprocVecEnv x {n_envs} | {n_envs} | {np.median(rates):,.0f} |"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--episodes", type=int, default=100, help="episodes per cheap controller (zero, random)")
    parser.add_argument("--expert-episodes", type=int, default=20)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--steps", type=int, default=4096, help="env steps per sampling measurement")
    parser.add_argument("--skip-sampling", action="store_true", help="only the sweep table")
    parser.add_argument("--skip-sweeps", action="store_true", help="only the sampling table")
    args = parser.parse_args()
    if args.skip_sampling and args.skip_sweeps:
        parser.error("--skip-sampling and --skip-sweeps together leave nothing to measure")

    from impact_env.transport.scenario import load_scenario
    from planners.offline.spatially_robust import plan_spatially_robust

    print(f"{os.cpu_count()} cores; load average before: {_load()}\n")
    if not args.skip_sweeps:
        os.makedirs("out", exist_ok=True)
        plan_path = str(plan_spatially_robust(load_scenario(SCENARIO)).save("out/ray_overhead_plan.json"))
        print("| controllers | engine | episodes | start-up s | sweep s | episodes/s | speed-up | same results |")
        print("|---|---|---:|---:|---:|---:|---:|---|")
        sweep_rows(["zero", "random"], args.episodes, args.workers, plan_path)
        sweep_rows(["expert"], args.expert_episodes, args.workers, plan_path)
        from impact_env.sweep import shutdown_ray

        shutdown_ray()  # the sampling rows start their own Ray
        print(f"\nload average after the sweeps: {_load()}")
    if args.skip_sampling:
        return
    print(f"\nSampling with the policy in the loop, median of 3 x {args.steps} env steps:\n")
    print("| sampler | processes | env steps/s |")
    print("|---|---:|---:|")
    for row in env_ceiling(2000):
        print(row, flush=True)
    for n in (1, 2):
        print(sb3_sampling(n, args.steps), flush=True)
    for n in (1, 2):
        print(rllib_sampling(n, args.steps), flush=True)
    print(f"\nload average after: {_load()}")


if __name__ == "__main__":
    main()
