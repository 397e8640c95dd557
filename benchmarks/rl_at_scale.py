"""RL at scale on the batched world: MAPPO and IPPO (BenchMARL) on every shipped scenario and on VMAS's
``transport``, and SB3's PPO through the batched ``VecEnv``, each run resumable, published to
``results/rl_at_scale/``.

    python -m benchmarks.rl_at_scale --workers 2 [--kinds mappo,ippo,vmas,sb3] [--seeds 0,1,2] [--frames 10000000]
    python -m benchmarks.rl_at_scale --publish          # only rebuild runs.jsonl, the table and the figures

Each run is a subprocess (``python -m baselines.batched.marl`` or ``python -m baselines.batched.sb3_ppo``; the
VMAS runs in the Python of ``--vmas-python`` / ``$VMAS_PYTHON``, a venv with vmas and benchmarl, since vmas pulls
the legacy gym) writing into its folder under ``--runs`` (default ``runs/rl_at_scale/``; checkpoints, logs,
``curve.jsonl``, and ``result.json`` when done), with its output in ``--logs`` (default ``/tmp/rl_at_scale/``).
Runs go in the order seed, then scenario, then algorithm, so the first seed of every cell finishes first. A
killed queue started again with the same command skips the finished runs and resumes the others from their
last checkpoint. After every run, ``results/rl_at_scale/`` is rebuilt from the run folders: ``runs.jsonl`` (one
line per finished run: algorithm, task, seed, env-step budget and steps done, wall clock, the final
evaluation on the batched world and on the pymunk env), ``curves/<run>.jsonl`` (the training curves), and,
with rliable (the ``[marl]`` extra), ``summary.md`` (interquartile means with 95 % stratified-bootstrap
intervals) and ``curves_steps.png`` / ``curves_wall.png``. Run from the repository's top folder.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "results" / "rl_at_scale"
SCENARIOS = ("corridor", "obstacle_avoidance", "throw_and_catch_exp", "ping_pong_stop", "relay", "two_objects",
             "long_throw_trim")
KINDS = ("mappo", "ippo", "vmas", "sb3")


@dataclass(frozen=True)
class Run:
    """One training run of the queue."""

    algorithm: str  # mappo, ippo, sb3_ppo
    task: str  # a scenario or vmas/transport
    seed: int
    frames: int

    @property
    def name(self) -> str:
        return f"{self.algorithm}__{self.task.replace('/', '_')}__s{self.seed}"

    def command(self, python: str, folder: Path, threads: int) -> list[str]:
        module = "baselines.batched.sb3_ppo" if self.algorithm == "sb3_ppo" else "baselines.batched.marl"
        args = [python, "-m", module]
        args += [self.task] if self.algorithm == "sb3_ppo" else [self.algorithm, self.task]
        return args + ["--seed", str(self.seed), "--frames", str(self.frames), "--out", str(folder),
                       "--threads", str(threads)]


def queue(kinds: list[str], seeds: list[int], frames: int, scenarios: list[str]) -> list[Run]:
    runs = []
    for seed in seeds:
        for scenario in scenarios:
            for algo in ("mappo", "ippo"):
                if algo in kinds:
                    runs.append(Run(algo, scenario, seed, frames))
            if "sb3" in kinds:
                runs.append(Run("sb3_ppo", scenario, seed, frames))
        if "vmas" in kinds:
            for algo in ("mappo", "ippo"):
                runs.append(Run(algo, "vmas/transport", seed, frames))
    return runs


def run_one(run: Run, runs_dir: Path, logs: Path, python: str, vmas_python: str | None, threads: int) -> str:
    folder = runs_dir / run.name
    if (folder / "result.json").exists():
        return f"{run.name}: done before"
    exe = vmas_python if run.task.startswith("vmas/") else python
    if exe is None:
        return f"{run.name}: skipped (no --vmas-python / $VMAS_PYTHON)"
    logs.mkdir(parents=True, exist_ok=True)
    env = {**os.environ,
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep),
           "OMP_NUM_THREADS": str(threads)}
    start = time.perf_counter()
    with (logs / f"{run.name}.log").open("a", encoding="utf-8") as log:
        log.write(f"\n=== start {time.strftime('%Y-%m-%d %H:%M:%S')}\n")
        log.flush()
        done = subprocess.run(run.command(exe, folder, threads), cwd=ROOT, env=env, stdout=log,
                              stderr=subprocess.STDOUT, check=False)
    status = "finished" if done.returncode == 0 else f"exited with {done.returncode} (log: {logs / run.name}.log)"
    return f"{run.name}: {status} after {time.perf_counter() - start:.0f} s"


def publish(runs_dir: Path, out: Path = RESULTS) -> list[dict]:
    """Rebuild ``out`` from the finished runs of ``runs_dir`` (and the curves of the unfinished ones)."""
    from impact_env.results_store import write_atomic

    rows = []
    (out / "curves").mkdir(parents=True, exist_ok=True)
    for folder in sorted(p for p in runs_dir.iterdir() if p.is_dir()) if runs_dir.exists() else []:
        curve = folder / "curve.jsonl"
        if curve.exists():
            shutil.copyfile(curve, out / "curves" / f"{folder.name}.jsonl")
        result = folder / "result.json"
        if result.exists():
            row = json.loads(result.read_text(encoding="utf-8"))
            rows.append({"run": folder.name, **row})
    write_atomic(out / "runs.jsonl", "".join(json.dumps(r, sort_keys=True) + "\n" for r in rows))
    try:
        from benchmarks.rl_at_scale_report import write_report
    except ImportError as exc:  # rliable or matplotlib missing
        print(f"no summary: {exc}")
    else:
        write_report(out)
    return rows


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--kinds", default="mappo,ippo,vmas,sb3", help=f"any of {','.join(KINDS)}")
    parser.add_argument("--seeds", default="0,1,2")
    parser.add_argument("--scenarios", default=",".join(SCENARIOS))
    parser.add_argument("--frames", type=int, default=10_000_000, help="env-step budget of every run")
    parser.add_argument("--workers", type=int, default=2, help="runs at once")
    parser.add_argument("--threads", type=int, default=1, help="torch threads per run")
    parser.add_argument("--runs", type=Path, default=ROOT / "runs" / "rl_at_scale")
    parser.add_argument("--logs", type=Path, default=Path("/tmp/rl_at_scale"))
    parser.add_argument("--vmas-python", default=os.environ.get("VMAS_PYTHON"))
    parser.add_argument("--publish", action="store_true", help="only rebuild results/rl_at_scale/")
    args = parser.parse_args(argv)
    if args.publish:
        rows = publish(args.runs)
        print(f"{len(rows)} finished runs in {RESULTS.relative_to(ROOT)}/runs.jsonl")
        return
    kinds = [k for k in args.kinds.split(",") if k]
    unknown = sorted(set(kinds) - set(KINDS))
    if unknown:
        raise SystemExit(f"--kinds: unknown {', '.join(unknown)}; choose from {', '.join(KINDS)}")
    runs = queue(kinds, [int(s) for s in args.seeds.split(",")], args.frames, args.scenarios.split(","))
    print(f"{len(runs)} runs, {args.workers} at a time; logs in {args.logs}", flush=True)
    with ThreadPoolExecutor(args.workers) as pool:
        futures = [pool.submit(run_one, r, args.runs, args.logs, sys.executable, args.vmas_python, args.threads)
                   for r in runs]
        for future in futures:
            print(future.result(), flush=True)
            publish(args.runs)


if __name__ == "__main__":
    main()
