"""Distribution parity of the batched world with the pymunk env: random-action episodes under 5 % thrust noise
and 5 cm start noise, the final robustness of each shipped scenario, two-sample Kolmogorov-Smirnov test.

The two backends draw their noise from different generators (Philox against numpy), so only distributions can
agree: the test passes at alpha = 0.01 when the p-value is above it. The pymunk env flies seeds 0 .. n-1 with
actions from ``numpy.random.default_rng(123)``; the batched world (float64, eager) flies n envs seeded
10,000 + i with actions from ``torch.Generator().manual_seed(456)``. ``tests/impact_env/transport/batched/
test_distributions.py`` runs the same functions at 30 (default suite) and 200 (slow suite) episodes. Each
scenario is a line of ``results/batched/parity.jsonl`` (atomic, so a rerun resumes; ``--episodes`` is part
of the key). From the repository root:

    python -m benchmarks.batched_parity [--episodes 1000] [--scenarios corridor,two_objects] [--table-only]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from impact_env.results_store import CellStore

RESULTS = Path(__file__).resolve().parents[1] / "results" / "batched" / "parity.jsonl"
ALPHA = 0.01
NOISE = {"thrust_noise": 0.05, "initial_position_noise_m": 0.05}


def pymunk_finals(name: str, episodes: int) -> np.ndarray:
    """Final robustness (m) of ``episodes`` random-action episodes of the pymunk Gym env."""
    from impact_env.transport.gym_env import TransportEnv

    env = TransportEnv(name, **NOISE)
    rng = np.random.default_rng(123)
    out = []
    for seed in range(episodes):
        env.reset(seed=seed)
        terminated = False
        while not terminated:
            _, _, terminated, _, info = env.step(rng.uniform(-1.0, 1.0, env.action_space.shape).astype(np.float32))
        out.append(info["robustness"])
    return np.array(out)


def batched_finals(name: str, episodes: int) -> np.ndarray:
    """Final robustness (m) of ``episodes`` random-action envs of the batched world (float64)."""
    import torch

    from impact_env.transport.batched import BatchedTransportWorld

    world = BatchedTransportWorld(name, episodes, dtype=torch.float64, **NOISE)
    world.reset(seeds=10_000)
    gen = torch.Generator().manual_seed(456)
    for _ in range(world.horizon_steps):
        _, _, terminated, _, info = world.step(torch.rand(episodes, world.action_size, generator=gen) * 2 - 1)
    assert bool(terminated.all())
    return info["robustness"].numpy()


def compare(name: str, episodes: int) -> dict:
    """The KS test of one scenario: p-value, statistic, both means and the wall clock of each backend."""
    from scipy import stats

    t0 = time.perf_counter()
    ref = pymunk_finals(name, episodes)
    t1 = time.perf_counter()
    got = batched_finals(name, episodes)
    t2 = time.perf_counter()
    result = stats.ks_2samp(ref, got)
    return {"scenario": name, "episodes": episodes, "ks_pvalue": float(result.pvalue),
            "ks_statistic": float(result.statistic), "passes": bool(result.pvalue > ALPHA),
            "pymunk_mean_m": float(ref.mean()), "batched_mean_m": float(got.mean()),
            "pymunk_std_m": float(ref.std()), "batched_std_m": float(got.std()),
            "pymunk_s": round(t1 - t0, 1), "batched_s": round(t2 - t1, 1), **NOISE}


def key_of(cell: dict) -> tuple[str, int]:
    return cell["scenario"], cell["episodes"]


def table(cells: list[dict]) -> str:
    lines = ["| scenario | episodes each | KS p-value | passes (alpha 0.01) | mean final robustness pymunk / "
             "batched (m) |", "|---|---:|---:|---|---|"]
    for c in cells:
        passes = "yes" if c["passes"] else "**no**"
        lines.append(f"| {c['scenario']} | {c['episodes']} | {c['ks_pvalue']:.3f} | {passes} | "
                     f"{c['pymunk_mean_m']:.3f} / {c['batched_mean_m']:.3f} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    from impact_env.transport.scenario import scenario_names

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, default=1000)
    parser.add_argument("--scenarios", default=",".join(scenario_names()))
    parser.add_argument("--out", type=Path, default=RESULTS)
    parser.add_argument("--table-only", action="store_true")
    args = parser.parse_args(argv)
    store = CellStore(args.out, key=key_of)
    names = args.scenarios.split(",")
    if not args.table_only:
        import torch

        torch.set_num_threads(1)
        for name in names:
            if (name, args.episodes) in store:
                continue
            cell = compare(name, args.episodes)
            store.put(cell)
            print(f"{name}: KS p = {cell['ks_pvalue']:.3f} ({args.episodes} episodes each; mean final robustness "
                  f"pymunk {cell['pymunk_mean_m']:.3f} m, batched {cell['batched_mean_m']:.3f} m)", flush=True)
    print(table([c for c in store.cells() if c["scenario"] in names and c["episodes"] == args.episodes]))


if __name__ == "__main__":
    main()
