"""The expert on the batched world: its success rate flying :class:`~impact_env.transport.batched.one_env.
BatchedOneEnv` against flying the pymunk env, in the robustness benchmark's nominal and combined cells.

The same expert (stack, cached offline plan of :mod:`benchmarks.robustness`), the same env options per seed
(:func:`benchmarks.robustness.env_options`: the combined condition is e +-0.2 by the seed's sign, 10 cm start
noise and 10 % thrust noise) and the same seeds fly both backends in this process, one episode after the other.
The nominal cell is one episode (nothing is random); the combined one ``--seeds`` (50). Noise comes from each
backend's own generator (numpy for pymunk, Philox for the batched world), so the seeds draw different
perturbations of the same size: the bar is the success rates' agreement within one episode per cell, not the
same episodes. Every (scenario, stack, condition, backend) is a line of ``results/batched/expert/cells.jsonl``,
written atomically when it is done (:class:`impact_env.results_store.CellStore`), so a rerun resumes. Prints
the table. From the repository root:

    python -m benchmarks.batched_expert [--scenarios corridor,throw_and_catch_exp] [--stacks paper] [--seeds 50]
        [--axes nominal,combined] [--table-only]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from impact_env.results_store import CellStore, write_atomic

RESULTS = Path(__file__).resolve().parents[1] / "results" / "batched" / "expert"
SCENARIOS = ("corridor", "obstacle_avoidance", "throw_and_catch_exp", "long_throw_trim")
BACKENDS = ("pymunk", "batched")
_EXPERTS: dict = {}


def _expert(scenario: str, stack: str):
    from benchmarks.robustness import RESULTS as ROBUSTNESS
    from benchmarks.robustness import expert_config, plan_for
    from impact_env.transport.scenario import load_scenario
    from planners.expert import Expert
    from planners.plan import Plan

    if (scenario, stack) not in _EXPERTS:
        plan = Plan.from_dict(plan_for(scenario, ROBUSTNESS))
        _EXPERTS[(scenario, stack)] = Expert(load_scenario(scenario), plan=plan, config=expert_config(stack))
    return _EXPERTS[(scenario, stack)]


def episode(scenario: str, stack: str, axis: str, seed: int, backend: str) -> dict:
    """One episode of the expert on ``backend``: success, final robustness (m), wall clock (s)."""
    import torch

    from benchmarks.robustness import env_options
    from impact_env.transport.batched.one_env import BatchedOneEnv
    from impact_env.transport.gym_env import TransportEnv

    expert = _expert(scenario, stack)
    options = env_options(expert.scenario, axis, 0.0, seed)
    env = TransportEnv(expert.scenario, **options) if backend == "pymunk" else BatchedOneEnv(
        expert.scenario, dtype=torch.float64, **options)
    start = time.perf_counter()
    obs, info = env.reset(seed=seed)
    expert.reset()
    done = False
    while not done:
        obs, _, terminated, truncated, info = env.step(expert.act(obs, info))
        done = terminated or truncated
    return {"seed": seed, "success": bool(info["is_success"]), "robustness": float(info["robustness"]),
            "wall_s": round(time.perf_counter() - start, 2)}


def key_of(cell: dict) -> tuple[str, str, str, str]:
    return cell["scenario"], cell["stack"], cell["axis"], cell["backend"]


def run(scenarios, stacks, axes, seeds: int, out: Path) -> CellStore:
    from benchmarks.robustness import cell_seeds

    store = CellStore(out / "cells.jsonl", key=key_of)
    for scenario in scenarios:
        for stack in stacks:
            for axis in axes:
                n = cell_seeds(axis, seeds)
                for backend in BACKENDS:
                    if (scenario, stack, axis, backend) in store:
                        continue
                    start = time.perf_counter()
                    eps = [episode(scenario, stack, axis, seed, backend) for seed in range(n)]
                    cell = {"scenario": scenario, "stack": stack, "axis": axis, "backend": backend, "seeds": n,
                            "successes": sum(e["success"] for e in eps), "episodes": eps,
                            "wall_s": round(time.perf_counter() - start, 1)}
                    store.put(cell)
                    print(f"{scenario} {stack} {axis} {backend}: {cell['successes']}/{n} "
                          f"({cell['wall_s']:.0f} s)", flush=True)
    return store


def table(store: CellStore) -> str:
    """One row per (scenario, stack, condition) with both backends' successes."""
    cells = {key_of(c): c for c in store.cells()}
    rows = sorted({k[:3] for k in cells}, key=lambda k: (SCENARIOS.index(k[0]) if k[0] in SCENARIOS else 99, k))
    lines = ["| scenario | stack | condition | seeds | pymunk successes | batched successes | within one |",
             "|---|---|---|---:|---:|---:|---|"]
    for k in rows:
        p, b = cells.get((*k, "pymunk")), cells.get((*k, "batched"))
        if p is None or b is None:
            continue
        within = "yes" if abs(p["successes"] - b["successes"]) <= 1 else "**no**"
        lines.append(f"| {k[0]} | {k[1]} | {k[2]} | {p['seeds']} | {p['successes']} | {b['successes']} | {within} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenarios", default=",".join(SCENARIOS))
    parser.add_argument("--stacks", default="paper")
    parser.add_argument("--axes", default="nominal,combined")
    parser.add_argument("--seeds", type=int, default=50, help="episodes of the combined cell")
    parser.add_argument("--out", type=Path, default=RESULTS)
    parser.add_argument("--table-only", action="store_true")
    args = parser.parse_args(argv)
    for axis in args.axes.split(","):
        if axis not in ("nominal", "combined"):
            parser.error(f"--axes: nominal or combined, got {axis!r}")
    if args.table_only:
        store = CellStore(args.out / "cells.jsonl", key=key_of)
    else:
        import torch

        torch.set_num_threads(1)
        store = run(args.scenarios.split(","), args.stacks.split(","), args.axes.split(","), args.seeds, args.out)
    text = table(store)
    print(text)
    write_atomic(args.out / "table.md", text + "\n")


if __name__ == "__main__":
    main()
