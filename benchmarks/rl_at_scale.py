"""RL at scale on the batched world: SB3's PPO (centralised, through the batched ``VecEnv``) and BenchMARL's
MAPPO and IPPO on every shipped scenario, and MAPPO/IPPO on VMAS's ``transport`` for reference; every run
resumable, published to ``results/rl_at_scale/``.

    python -m benchmarks.rl_at_scale --kinds sb3 --frames 3000000        # the queue: 2 runs at a time
    python -m benchmarks.rl_at_scale --kinds sb3 --frames 3000000 --status   # what is done, what remains
    python -m benchmarks.rl_at_scale --publish       # only rebuild results/rl_at_scale/ from the run folders

A cell is one run: (algorithm, task, seed). Each is a subprocess (``python -m baselines.batched.sb3_ppo`` or
``python -m baselines.batched.marl``; the VMAS runs in the Python of ``--vmas-python`` / ``$VMAS_PYTHON``, a
venv with vmas and benchmarl, since vmas pulls the legacy gym) that trains in its folder under ``--runs``
(default ``runs/rl_at_scale/<algorithm>__<task>__s<seed>/``: checkpoints every ~1M env-steps, ``curve.jsonl``,
and ``result.json`` when the budget is spent and the final evaluation done), with its output in ``--logs``
(default ``<runs>/logs/``). ``--trainer-args`` passes further options to every trainer.
Runs go in the order seed, then scenario, then algorithm, so the first seed of every scenario finishes
first. A killed queue started again with the same command skips the finished cells and resumes the others
from their last checkpoint. On a new machine (no run folders), the cells already in ``--out``/cells.jsonl count
as finished: their ``result.json`` is written back from the published cell (:func:`restore`) before the queue
starts, so only the missing runs train (a restored run has no checkpoint, so a larger ``--frames`` trains it
again from the start). A larger ``--frames`` than a finished cell's budget trains that cell on from its
last checkpoint (its earlier result is kept as ``result_<budget>.json``).

After every run, ``results/rl_at_scale/`` is rebuilt from the run folders (:func:`publish`): ``cells.jsonl``
(:class:`~impact_env.results_store.CellStore`, one line per finished cell: algorithm, task, seed, env-step
budget and steps done, wall clock, throughput, the final evaluation on the batched world and on the pymunk
env, the configuration), ``curves/<run>.jsonl`` (training curves: env-steps, wall clock, mean return,
success rate, final robustness) and, with rliable and matplotlib (the ``[rl-analysis]`` extra),
:mod:`benchmarks.rl_at_scale_report`'s ``summary.md`` and figures. Run from the repository's top folder.
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "results" / "rl_at_scale"
SCENARIOS = ("corridor", "obstacle_avoidance", "throw_and_catch_exp", "ping_pong_stop", "relay", "two_objects",
             "long_throw_trim")
KINDS = ("sb3", "mappo", "ippo", "vmas")
VMAS_TASK = "vmas/transport"


def cell_key(cell: dict) -> tuple[str, str, int]:
    """A cell of ``cells.jsonl`` is named by (algorithm, task, seed)."""
    return (str(cell["algorithm"]), str(cell["task"]), int(cell["seed"]))


@dataclass(frozen=True)
class Run:
    """One training run (one cell) of the queue."""

    algorithm: str  # sb3_ppo, mappo, ippo
    task: str  # a scenario or vmas/transport
    seed: int
    frames: int  # env-step budget
    compile: bool = False  # sb3_ppo: the world's torch.compile kernels
    trainer_args: tuple[str, ...] = ()  # further options of the trainer's command line (e.g. --num-envs 64)

    @property
    def name(self) -> str:
        return f"{self.algorithm}__{self.task.replace('/', '_')}__s{self.seed}"

    def command(self, python: str, folder: Path, threads: int) -> list[str]:
        if self.algorithm == "sb3_ppo":
            args = [python, "-m", "baselines.batched.sb3_ppo", self.task] + (["--compile"] if self.compile else [])
        else:
            args = [python, "-m", "baselines.batched.marl", self.algorithm, self.task]
        return args + ["--seed", str(self.seed), "--frames", str(self.frames), "--out", str(folder),
                       "--threads", str(threads), *self.trainer_args]


def queue(kinds: list[str], seeds: list[int], frames: int, scenarios: list[str], compile: bool = False,
          trainer_args: tuple[str, ...] = ()) -> list[Run]:
    """The runs of ``kinds`` (any of :data:`KINDS`), seed by seed: every scenario's, then VMAS's."""
    unknown = sorted(set(kinds) - set(KINDS))
    if unknown:
        raise ValueError(f"unknown kinds {', '.join(unknown)}; choose from {', '.join(KINDS)}")
    if frames < 1:
        raise ValueError(f"frames must be >= 1, got {frames}")
    runs = []
    for seed in seeds:
        for scenario in scenarios:
            if "sb3" in kinds:
                runs.append(Run("sb3_ppo", scenario, seed, frames, compile, trainer_args))
            runs += [Run(algo, scenario, seed, frames, trainer_args=trainer_args) for algo in ("mappo", "ippo")
                     if algo in kinds]
        if "vmas" in kinds:
            runs += [Run(algo, VMAS_TASK, seed, frames, trainer_args=trainer_args) for algo in ("mappo", "ippo")]
    return runs


def _read_json(path: Path) -> dict | None:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


def status(run: Run, runs_dir: Path) -> tuple[str, int]:
    """(``done``, ``partial``, ``pending`` or ``extend``, env-steps trained so far) of a run."""
    folder = runs_dir / run.name
    result = _read_json(folder / "result.json")
    if result is not None:
        return ("done" if result["budget_env_steps"] >= run.frames else "extend"), int(result["env_steps"])
    state = _read_json(folder / "state.json")  # sb3_ppo's checkpoint
    if state is not None:
        return "partial", int(state["frames"])
    curve = folder / "curve.jsonl"
    if curve.exists():
        lines = [line for line in curve.read_text(encoding="utf-8").splitlines() if line.strip()]
        if lines:
            return "partial", int(json.loads(lines[-1])["frames"])
    return "pending", 0


def run_one(run: Run, runs_dir: Path, logs: Path, python: str, vmas_python: str | None, threads: int) -> str:
    """Train (or resume, or extend) one run in its subprocess; a line saying what happened."""
    folder = runs_dir / run.name
    state, _ = status(run, runs_dir)
    if state == "done":
        return f"{run.name}: done before"
    if state == "extend":  # a larger budget: train on from the last checkpoint, keep the earlier result
        old = _read_json(folder / "result.json")
        os.replace(folder / "result.json", folder / f"result_{old['budget_env_steps']}.json")
    exe = vmas_python if run.task.startswith("vmas/") else python
    if exe is None:
        return f"{run.name}: skipped (no --vmas-python / $VMAS_PYTHON)"
    logs.mkdir(parents=True, exist_ok=True)
    path = os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH", "")) if p)
    env = {**os.environ, "PYTHONPATH": path, "OMP_NUM_THREADS": str(threads)}
    start = time.perf_counter()
    log_path = logs / f"{run.name}.log"
    with log_path.open("a", encoding="utf-8") as log:
        log.write(f"\n=== start {time.strftime('%Y-%m-%d %H:%M:%S')}: {' '.join(run.command(exe, folder, threads))}\n")
        log.flush()
        done = subprocess.run(run.command(exe, folder, threads), cwd=ROOT, env=env, stdout=log,
                              stderr=subprocess.STDOUT, check=False)
    outcome = "finished" if done.returncode == 0 else f"exited with {done.returncode} (log: {log_path})"
    return f"{run.name}: {outcome} after {time.perf_counter() - start:.0f} s"


def publish(runs_dir: Path, out: Path = RESULTS, report: bool = True) -> list[dict]:
    """Rebuild ``out`` from ``runs_dir``: every finished run's cell in ``cells.jsonl`` (put through CellStore, so
    the file is rewritten atomically and keeps its order), every run's curve in ``curves/``; then the report
    (when rliable and matplotlib are installed). Returns the cells."""
    from impact_env.results_store import CellStore, write_atomic

    store = CellStore(out / "cells.jsonl", cell_key)
    folders = sorted(p for p in runs_dir.iterdir() if p.is_dir()) if runs_dir.exists() else []
    for folder in folders:
        curve = folder / "curve.jsonl"
        if curve.exists():
            write_atomic(out / "curves" / f"{folder.name}.jsonl", curve.read_bytes())
        result = _read_json(folder / "result.json")
        if result is not None:
            cell = {"run": folder.name, **result}
            if store.get(cell_key(cell)) != json.loads(json.dumps(cell)):
                store.put(cell)
    if report:
        try:
            from benchmarks.rl_at_scale_report import write_report
        except ImportError as exc:  # rliable or matplotlib missing
            print(f"no summary ({exc}); pip install -e '.[rl-analysis]'", flush=True)
        else:
            write_report(out)
    return store.cells()


def restore(out: Path, runs_dir: Path) -> list[str]:
    """Write ``result.json`` back into the run folder of every published cell of ``out``/cells.jsonl whose folder
    has none (a new machine, or run folders deleted), so that :func:`status` sees it as finished and the queue does
    not train it again (a run being extended to a larger budget finds its earlier result there and goes on from
    its checkpoint). Returns the names of the runs restored."""
    from impact_env.results_store import CellStore, write_atomic

    restored = []
    for cell in CellStore(out / "cells.jsonl", cell_key).cells():
        folder = runs_dir / str(cell["run"])
        if (folder / "result.json").exists():
            continue
        result = {k: v for k, v in cell.items() if k != "run"}
        write_atomic(folder / "result.json", json.dumps(result).encode("utf-8"))
        restored.append(folder.name)
    return restored


def print_status(runs: list[Run], runs_dir: Path) -> dict[str, int]:
    counts = {"done": 0, "partial": 0, "pending": 0, "extend": 0}
    for run in runs:
        state, steps = status(run, runs_dir)
        counts[state] += 1
        print(f"  {state:8s} {run.name:48s} {steps:>12,} / {run.frames:,} env-steps")
    print(", ".join(f"{n} {k}" for k, n in counts.items()))
    return counts


def status_markdown(runs: list[Run], runs_dir: Path, command: str) -> str:
    """What of the queue has run and what remains, for a docs page: counts, env-steps, and the command that
    finishes the rest."""
    states = [(run, *status(run, runs_dir)) for run in runs]
    done = [r for r, s, _ in states if s == "done"]
    partial = [(r, n) for r, s, n in states if s in ("partial", "extend")]
    pending = [r for r, s, _ in states if s == "pending"]
    lines = [f"**What ran.** {len(done)} of the {len(runs)} runs of `{command}` finished "
             f"({', '.join(sorted({r.algorithm for r in runs}))}, budget {runs[0].frames:,} env-steps a run, seeds "
             f"{','.join(map(str, sorted({r.seed for r in runs})))})."]
    if partial or pending:
        parts = [f"{r.name} ({n:,} env-steps)" for r, n in partial] + [r.name for r in pending]
        lines.append(f"**What remains:** {', '.join(parts)}. The same command trains them (the partial ones from "
                     "their last checkpoint) and rebuilds these tables.")
    return " ".join(lines) + "\n"


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--kinds", default="sb3", help=f"any of {','.join(KINDS)} (comma-separated)")
    parser.add_argument("--seeds", default="0,1,2")
    parser.add_argument("--scenarios", default=",".join(SCENARIOS))
    parser.add_argument("--frames", type=int, default=10_000_000, help="env-step budget of every run")
    parser.add_argument("--workers", type=int, default=2, help="runs at once")
    parser.add_argument("--threads", type=int, default=1, help="torch threads per run")
    parser.add_argument("--compile", action="store_true", help="sb3_ppo: the world's torch.compile kernels")
    parser.add_argument("--trainer-args", default="", help="further trainer options, one string (e.g. "
                        "'--num-envs 512 --eval-episodes 50'): the same for every run of the queue")
    parser.add_argument("--runs", type=Path, default=ROOT / "runs" / "rl_at_scale", help="run folders")
    parser.add_argument("--out", type=Path, default=RESULTS, help="the published results")
    parser.add_argument("--logs", type=Path, default=None, help="the runs' output (default <runs>/logs)")
    parser.add_argument("--vmas-python", default=os.environ.get("VMAS_PYTHON"))
    parser.add_argument("--status", action="store_true", help="list the queue's runs and their state, then exit")
    parser.add_argument("--publish", action="store_true", help="only rebuild --out from the run folders")
    parser.add_argument("--status-md", type=Path, default=None, help="with --status: also write what ran and "
                        "what remains as a markdown paragraph to this file (benchmarks.rl_at_scale_report --docs "
                        "--status reads it)")
    args = parser.parse_args(argv)
    if args.publish:
        cells = publish(args.runs, args.out)
        print(f"{len(cells)} finished cells in {args.out}/cells.jsonl")
        return
    restored = restore(args.out, args.runs)
    if restored:
        print(f"{len(restored)} finished run(s) restored from {args.out}/cells.jsonl into {args.runs}", flush=True)
    try:
        runs = queue([k for k in args.kinds.split(",") if k], [int(s) for s in args.seeds.split(",")], args.frames,
                     [s for s in args.scenarios.split(",") if s], args.compile, tuple(shlex.split(args.trainer_args)))
    except ValueError as exc:
        raise SystemExit(f"rl_at_scale: {exc}") from None
    if args.status:
        print_status(runs, args.runs)
        if args.status_md:
            from impact_env.results_store import write_atomic

            given = [a for a in (argv if argv is not None else sys.argv[1:]) if a != "--status"]
            cut = given.index("--status-md") if "--status-md" in given else len(given)
            command = " ".join(["python -m benchmarks.rl_at_scale", *given[:cut], *given[cut + 2:]])
            write_atomic(args.status_md, status_markdown(runs, args.runs, command))
        return
    logs = args.logs or args.runs / "logs"
    todo = [r for r in runs if status(r, args.runs)[0] != "done"]
    print(f"{len(runs)} runs, {len(runs) - len(todo)} done before; {len(todo)} to train, {args.workers} at a time "
          f"({args.threads} torch thread(s) each); logs in {logs}", flush=True)
    start = time.perf_counter()
    with ThreadPoolExecutor(args.workers) as pool:
        futures = [pool.submit(run_one, r, args.runs, logs, sys.executable, args.vmas_python, args.threads)
                   for r in todo]
        for i, future in enumerate(as_completed(futures), start=1):
            print(f"[{i}/{len(todo)}, {time.perf_counter() - start:.0f} s] {future.result()}", flush=True)
            publish(args.runs, args.out)
    publish(args.runs, args.out)


if __name__ == "__main__":
    main()
