"""Batched-world throughput: env-steps/s against num_envs, with VMAS and the pymunk env in the same run.

Rows, all at the same torch thread count, random actions in [-1, 1], after a warm-up (which includes
torch.compile's first compilation):

- the batched world (:class:`impact_env.transport.batched.BatchedTransportWorld`) on the CPU, and on a GPU
  when one is present, for each ``--num-envs``; envs that reach the horizon are reset (``reset(mask=...)``);
- VMAS's ``transport`` scenario (4 agents, continuous actions, float32, CPU) at the same num_envs, run by a
  subprocess in the Python given by ``--vmas-python`` or ``$VMAS_PYTHON`` (a venv with ``vmas`` and
  ``torch==2.13.0``: vmas pulls the legacy ``gym``, so it never enters this package's install); skipped with a
  message when neither is given;
- the pymunk Gymnasium env (``TransportEnv``, one process), measured before and after the batched rows, of
  this tree and of the reference commit ``--ref`` (default 0378a64, the batched world's starting point, exported
  with :func:`benchmarks.git_tree.export_tree` and run in its own process).

Prints a markdown table and appends one JSON line per measurement to ``results/batched/throughput.jsonl``
(rewritten atomically: temporary file, then ``os.replace``). Run from the repository's top folder:

    python -m benchmarks.batched [--scenario corridor] [--num-envs 1 16 256 1024 4096 16384] [--threads 2]
        [--seconds 5] [--dtype float32] [--eager] [--vmas-python PATH] [--ref 0378a64 | --ref ""]
    python -m benchmarks.batched --table-only     # the tables of the last run in the results file

Each row runs for ``--seconds`` of its process's CPU time (all threads) and records two rates: env-steps per
second of the wall clock (``env_steps_per_s``, the measure on an idle machine) and per second of CPU time
(``env_steps_per_cpu_s``), which the other jobs of a shared machine do not enter. A loop of T threads that
keeps them all busy shows T times its wall rate's worth of CPU time, so on an idle machine the CPU rate of a
2-thread row is up to half its wall rate; the pymunk rows are one thread. On a shared machine, compare rows
of the same run (the load average is recorded with every line); the table prints both. Under load, run it
with ``OMP_WAIT_POLICY=PASSIVE`` (recorded with every line; the VMAS subprocess inherits it): OpenMP's
threads then sleep at a barrier instead of spinning, so a thread that waits for a descheduled one burns no
CPU time. On an idle machine leave it unset: there, sleeping at every barrier cost the 2-thread batched world
two thirds of its rate at 4,096 envs (docs/batched.md, "OpenMP's wait policy").
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from benchmarks.git_tree import export_tree, run_in_tree

RESULTS = Path(__file__).resolve().parents[1] / "results" / "batched" / "throughput.jsonl"
POOL = 64  # random action batches drawn up front and cycled, for every backend alike

VMAS_SCRIPT = r"""
import json, sys, time
import torch
import vmas
num_envs, threads, seconds = int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3])
torch.set_num_threads(threads)
env = vmas.make_env("transport", num_envs=num_envs, device="cpu", continuous_actions=True, seed=0)
env.reset()
gen = torch.Generator().manual_seed(0)
pool = [[torch.rand(num_envs, 2, generator=gen) * 2 - 1 for _ in env.agents] for _ in range(64)]
for k in range(20):
    env.step(pool[k % 64])
steps, start, cpu = 0, time.perf_counter(), time.process_time()
while time.process_time() - cpu < seconds:
    env.step(pool[steps % 64])
    steps += 1
elapsed, cpu_s = time.perf_counter() - start, time.process_time() - cpu
print(json.dumps({"env_steps_per_s": steps * num_envs / elapsed, "env_steps_per_cpu_s": steps * num_envs / cpu_s,
                  "steps": steps, "seconds": elapsed, "cpu_s": cpu_s, "vmas": vmas.__version__,
                  "agents": len(env.agents)}))
"""


def measure_batched(scenario: str, num_envs: int, seconds: float, dtype: str, device: str, compile_: bool) -> dict:
    import torch

    from impact_env.transport.batched import BatchedTransportWorld

    start = time.perf_counter()
    world = BatchedTransportWorld(scenario, num_envs, device=device, dtype=getattr(torch, dtype), compile=compile_)
    world.reset(seeds=0)
    gen = torch.Generator().manual_seed(0)
    pool = [(torch.rand(num_envs, world.action_size, generator=gen) * 2 - 1).to(device) for _ in range(POOL)]
    for k in range(20):
        world.step(pool[k % POOL])
    warmup = time.perf_counter() - start
    steps, start, cpu = 0, time.perf_counter(), time.process_time()
    while time.process_time() - cpu < seconds:
        _, _, terminated, _, _ = world.step(pool[steps % POOL])
        steps += 1
        if bool(terminated.any()):
            world.reset(mask=terminated)
    if device.startswith("cuda"):
        torch.cuda.synchronize()
    elapsed, cpu_s = time.perf_counter() - start, time.process_time() - cpu
    return {"env_steps_per_s": steps * num_envs / elapsed, "env_steps_per_cpu_s": steps * num_envs / cpu_s,
            "steps": steps, "seconds": elapsed, "cpu_s": cpu_s, "warmup_s": warmup}


def measure_pymunk(scenario: str, seconds: float) -> dict:
    """The Gym env's rate (one process), random actions, resets at the horizon. It imports the env from
    ``impact_env.envs``, which both this tree and the reference commit's have, so that it runs in either."""
    from impact_env.envs import TransportEnv

    env = TransportEnv(scenario)
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    pool = rng.uniform(-1.0, 1.0, (POOL * 16, *env.action_space.shape)).astype(np.float32)
    for k in range(100):
        env.step(pool[k])
    steps, start, cpu = 0, time.perf_counter(), time.process_time()
    while time.process_time() - cpu < seconds:
        _, _, terminated, _, _ = env.step(pool[steps % len(pool)])
        steps += 1
        if terminated:
            env.reset()
    elapsed, cpu_s = time.perf_counter() - start, time.process_time() - cpu
    return {"env_steps_per_s": steps / elapsed, "env_steps_per_cpu_s": steps / cpu_s, "steps": steps,
            "seconds": elapsed, "cpu_s": cpu_s}


def measure_vmas(python: str, num_envs: int, threads: int, seconds: float) -> dict | str:
    """The subprocess's measurement, or the reason it failed."""
    try:
        out = subprocess.run([python, "-c", VMAS_SCRIPT, str(num_envs), str(threads), str(seconds)], check=True,
                             capture_output=True, text=True, timeout=600 + 10 * seconds)
    except (OSError, subprocess.SubprocessError) as exc:
        stderr = getattr(exc, "stderr", "") or ""
        return f"{type(exc).__name__}: {stderr.strip().splitlines()[-1] if stderr.strip() else exc}"
    return json.loads(out.stdout.strip().splitlines()[-1])


def append_results(lines: list[dict], path: Path = RESULTS) -> None:
    """Append JSON lines to ``path``, atomically: the whole file is written to a temporary file and replaced."""
    path.parent.mkdir(parents=True, exist_ok=True)
    old = path.read_text(encoding="utf-8") if path.exists() else ""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(old + "".join(json.dumps(line, sort_keys=True) + "\n" for line in lines))
        os.replace(tmp, path)
    except BaseException:
        os.unlink(tmp)
        raise


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenario", default="corridor")
    parser.add_argument("--num-envs", type=int, nargs="+", default=[1, 16, 256, 1024, 4096, 16384])
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--seconds", type=float, default=5.0,
                        help="CPU time each row runs for, after the warm-up (the process's, all its threads)")
    parser.add_argument("--dtype", choices=("float32", "float64"), default="float32")
    parser.add_argument("--eager", action="store_true", help="the batched world without torch.compile")
    parser.add_argument("--vmas-python", default=os.environ.get("VMAS_PYTHON"),
                        help="python of a venv with vmas (default: $VMAS_PYTHON)")
    parser.add_argument("--ref", default="0378a64",
                        help="commit whose pymunk Gym env is measured in the same run ('' to skip)")
    parser.add_argument("--no-write", action="store_true", help="print only, do not append to the results")
    parser.add_argument("--table-only", action="store_true",
                        help="print the tables of the last run in the results file, measure nothing")
    args = parser.parse_args(argv)
    if args.table_only:
        lines = [json.loads(line) for line in RESULTS.read_text(encoding="utf-8").splitlines() if line.strip()]
        last = max(line["run"] for line in lines)
        print(f"run {last}: {next(line['command'] for line in lines if line['run'] == last)}")
        print_table([line for line in lines if line["run"] == last])
        return

    import torch

    torch.set_num_threads(args.threads)
    devices = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
    run = {"run": datetime.now(timezone.utc).isoformat(timespec="seconds"), "scenario": args.scenario,
           "threads": args.threads, "dtype": args.dtype, "torch": torch.__version__, "machine": platform.machine(),
           "cpus": os.cpu_count(), "command": "python -m benchmarks.batched " + " ".join(sys.argv[1:]),
           "omp_wait_policy": os.environ.get("OMP_WAIT_POLICY")}
    lines: list[dict] = []

    def record(backend: str, num_envs: int, result: dict) -> None:
        lines.append({**run, **result, "backend": backend, "num_envs": num_envs,
                      "load_average_1min": round(os.getloadavg()[0], 2)})

    tree = export_tree(args.ref) if args.ref else None

    def pymunk_rows() -> None:
        record("pymunk-gym", 1, measure_pymunk(args.scenario, args.seconds))
        if tree is not None:
            record(f"pymunk-gym@{args.ref}", 1,
                   run_in_tree(tree, "benchmarks.batched:measure_pymunk", args.scenario, args.seconds))

    pymunk_rows()
    if not args.vmas_python:
        print("VMAS not measured: pass --vmas-python PATH (a venv with vmas and torch==2.13.0) or set VMAS_PYTHON")
    for n in args.num_envs:
        for device in devices:
            result = measure_batched(args.scenario, n, args.seconds, args.dtype, device, not args.eager)
            record(f"batched-{device}{'' if not args.eager else '-eager'}", n, result)
            print(f"batched {device} N={n}: {result['env_steps_per_s']:,.0f} env-steps/s", flush=True)
        if args.vmas_python:
            result = measure_vmas(args.vmas_python, n, args.threads, args.seconds)
            if isinstance(result, str):
                print(f"VMAS N={n} failed: {result}")
            else:
                record("vmas-cpu", n, result)
                print(f"VMAS N={n}: {result['env_steps_per_s']:,.0f} env-steps/s", flush=True)
    pymunk_rows()
    print_table(lines)
    if not args.no_write:
        append_results(lines)
        print(f"\nappended {len(lines)} lines to {RESULTS.relative_to(RESULTS.parents[2])}")


def print_table(lines: list[dict]) -> None:
    """Both tables of the run: by the wall clock, then by CPU time (where every row has it)."""
    _print_table(lines, "env_steps_per_s", "wall clock")
    if all("env_steps_per_cpu_s" in line for line in lines):
        _print_table(lines, "env_steps_per_cpu_s", "CPU time")


def _print_table(lines: list[dict], rate_key: str, clock: str) -> None:
    """The run's markdown table: one row per num_envs, the batched rates against the pymunk env's (the mean of
    its rows; of this tree and of the reference commit) and VMAS's at the same num_envs."""
    pymunk_backends = sorted({line["backend"] for line in lines if line["backend"].startswith("pymunk-gym")})
    pymunk_rate = {b: float(np.mean([line[rate_key] for line in lines if line["backend"] == b]))
                   for b in pymunk_backends}
    rates: dict[tuple[str, int], float] = {(line["backend"], line["num_envs"]): line[rate_key]
                                           for line in lines if not line["backend"].startswith("pymunk-gym")}
    backends = sorted({b for b, _ in rates}, key=lambda b: (b.startswith("vmas"), b))
    first = lines[0]
    pymunk_text = "; ".join(f"{b}: {r:,.0f}" for b, r in pymunk_rate.items())
    print(f"\nBy the {clock}: {first['scenario']}, dense STL reward, {first['dtype']}, {first['threads']} torch "
          f"threads; pymunk Gymnasium env (one process, mean of the runs before and after), env-steps/s: "
          f"{pymunk_text}\n")
    batched = [b for b in backends if b.startswith("batched")]
    header = ["num_envs", *[f"{b} env-steps/s" for b in backends]]
    header += [f"{b} / {p}" for b in batched for p in pymunk_backends]
    header += [f"{b} / VMAS" for b in batched] if "vmas-cpu" in backends else []
    print("| " + " | ".join(header) + " |")
    print("|" + "---:|" * len(header))
    for n in sorted({n for _, n in rates}):
        cells = [str(n)] + [f"{rates[(b, n)]:,.0f}" if (b, n) in rates else "-" for b in backends]
        cells += [f"{rates[(b, n)] / pymunk_rate[p]:.1f}x" if (b, n) in rates else "-" for b in batched
                  for p in pymunk_backends]
        if "vmas-cpu" in backends:
            cells += [f"{rates[(b, n)] / rates[('vmas-cpu', n)]:.1f}x" if (b, n) in rates and ("vmas-cpu", n) in rates
                      else "-" for b in batched]
        print("| " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
