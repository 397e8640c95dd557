"""Distribution parity of the batched world with the pymunk env: random-action episodes under 5 % thrust noise
and 5 cm start noise, the final robustness of each shipped scenario, two-sample Kolmogorov-Smirnov test.

The two backends draw their noise from different generators (Philox against numpy), so only distributions can
agree: the test passes at alpha = 0.01 when the p-value is above it. Draw 0 (the default): the pymunk env flies
seeds 0 .. n-1 with actions from ``numpy.random.default_rng(123)``; the batched world (float64, eager) flies n
envs seeded 10,000 + i with actions from ``torch.Generator().manual_seed(456)``. Draw d > 0 (``--draws``) is an
independent replication: seeds shifted by 100,000 d on both sides, action generators seeded 123 + d and
456 + d. A single draw fails a true null at alpha = 0.01 one time in a hundred, so a scenario that fails draw 0
is judged on fresh draws fixed in advance: the table of replications prints each draw's p-value, how many
pass, and Fisher's combined p-value over them. ``tests/impact_env/transport/batched/
test_distributions.py`` runs the same functions at 30 (default suite) and 200 (slow suite) episodes. Each
scenario is a line of ``results/batched/parity.jsonl`` (atomic, so a rerun resumes; ``--episodes`` is part
of the key). From the repository root:

    python -m benchmarks.batched_parity [--episodes 1000] [--scenarios corridor,two_objects] [--draws 8]
                                         [--table-only]
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


DRAW_SEED_SHIFT = 100_000  # draw d's seeds on both sides: shifted by d times this


def pymunk_finals(name: str, episodes: int, draw: int = 0) -> np.ndarray:
    """Final robustness (m) of ``episodes`` random-action episodes of the pymunk Gym env (seeds of ``draw``)."""
    from impact_env.transport.gym_env import TransportEnv

    env = TransportEnv(name, **NOISE)
    rng = np.random.default_rng(123 + draw)
    out = []
    first = DRAW_SEED_SHIFT * draw
    for seed in range(first, first + episodes):
        env.reset(seed=seed)
        terminated = False
        while not terminated:
            _, _, terminated, _, info = env.step(rng.uniform(-1.0, 1.0, env.action_space.shape).astype(np.float32))
        out.append(info["robustness"])
    return np.array(out)


def batched_finals(name: str, episodes: int, draw: int = 0) -> np.ndarray:
    """Final robustness (m) of ``episodes`` random-action envs of the batched world (float64; seeds of ``draw``)."""
    import torch

    from impact_env.transport.batched import BatchedTransportWorld

    world = BatchedTransportWorld(name, episodes, dtype=torch.float64, **NOISE)
    world.reset(seeds=10_000 + DRAW_SEED_SHIFT * draw)
    gen = torch.Generator().manual_seed(456 + draw)
    for _ in range(world.horizon_steps):
        _, _, terminated, _, info = world.step(torch.rand(episodes, world.action_size, generator=gen) * 2 - 1)
    assert bool(terminated.all())
    return info["robustness"].numpy()


def compare(name: str, episodes: int, draw: int = 0) -> dict:
    """The KS test of one scenario and draw: p-value, statistic, both means and the wall clock of each backend."""
    from scipy import stats

    t0 = time.perf_counter()
    ref = pymunk_finals(name, episodes, draw)
    t1 = time.perf_counter()
    got = batched_finals(name, episodes, draw)
    t2 = time.perf_counter()
    result = stats.ks_2samp(ref, got)
    return {"scenario": name, "episodes": episodes, "ks_pvalue": float(result.pvalue),
            "ks_statistic": float(result.statistic), "passes": bool(result.pvalue > ALPHA),
            "pymunk_mean_m": float(ref.mean()), "batched_mean_m": float(got.mean()),
            "pymunk_std_m": float(ref.std()), "batched_std_m": float(got.std()),
            "pymunk_s": round(t1 - t0, 1), "batched_s": round(t2 - t1, 1), **NOISE, **({"draw": draw} if draw else {})}


def key_of(cell: dict) -> tuple[str, int, int]:
    return cell["scenario"], cell["episodes"], cell.get("draw", 0)


def holm(pvalues: list[float]) -> list[float]:
    """Holm's step-down adjustment of m p-values (family-wise error over the table's m tests): the k-th smallest is
    multiplied by m - k + 1, kept monotone and capped at 1. Four lines, so no statsmodels for it."""
    order = sorted(range(len(pvalues)), key=pvalues.__getitem__)
    adjusted, running = [0.0] * len(pvalues), 0.0
    for k, i in enumerate(order):
        running = max(running, min(1.0, (len(pvalues) - k) * pvalues[i]))
        adjusted[i] = running
    return adjusted


def table(cells: list[dict]) -> str:
    """One row per cell: its KS p-value against alpha, and Holm's adjustment over all the rows (the chance that
    any of the m scenarios fails a true null at alpha is up to m alpha, 12 % for 13 scenarios)."""
    lines = ["| scenario | episodes each | KS p-value | passes (alpha 0.01) | Holm-adjusted p (all rows) | mean final "
             "robustness pymunk / batched (m) |", "|---|---:|---:|---|---:|---|"]
    for c, adjusted in zip(cells, holm([c["ks_pvalue"] for c in cells])):
        passes = "yes" if c["passes"] else "**no**"
        lines.append(f"| {c['scenario']} | {c['episodes']} | {c['ks_pvalue']:.3f} | {passes} | {adjusted:.3f} | "
                     f"{c['pymunk_mean_m']:.3f} / {c['batched_mean_m']:.3f} |")
    return "\n".join(lines)


def replications(cells: list[dict]) -> str:
    """Per scenario and episode count with draws beyond 0: each replication's p-value, how many pass, Fisher's
    combined p-value over the replications (draw 0 excluded: it is the draw that asked for them)."""
    from scipy import stats

    groups: dict[tuple[str, int], list[dict]] = {}
    for c in cells:
        if c.get("draw", 0):
            groups.setdefault((c["scenario"], c["episodes"]), []).append(c)
    if not groups:
        return ""
    lines = ["| scenario | episodes each | fresh draws | KS p-values | pass (alpha 0.01) | Fisher's combined p |",
             "|---|---:|---:|---|---:|---:|"]
    for (name, episodes), group in groups.items():
        ps = [c["ks_pvalue"] for c in sorted(group, key=lambda c: c["draw"])]
        combined = stats.combine_pvalues(ps, method="fisher").pvalue
        lines.append(f"| {name} | {episodes} | {len(ps)} | {', '.join(f'{p:.3f}' for p in ps)} | "
                     f"{sum(p > ALPHA for p in ps)} of {len(ps)} | {combined:.3f} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    from impact_env.transport.scenario import scenario_names

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, default=1000)
    parser.add_argument("--scenarios", default=",".join(scenario_names()))
    parser.add_argument("--draws", type=int, default=0,
                        help="independent replications 1..DRAWS besides draw 0 (fresh seeds on both sides)")
    parser.add_argument("--out", type=Path, default=RESULTS)
    parser.add_argument("--table-only", action="store_true")
    args = parser.parse_args(argv)
    store = CellStore(args.out, key=key_of)
    names = args.scenarios.split(",")
    if not args.table_only:
        import torch

        torch.set_num_threads(1)
        for name in names:
            for draw in range(args.draws + 1):
                if (name, args.episodes, draw) in store:
                    continue
                cell = compare(name, args.episodes, draw)
                store.put(cell)
                print(f"{name}, draw {draw}: KS p = {cell['ks_pvalue']:.3f} ({args.episodes} episodes each; mean final "
                      f"robustness pymunk {cell['pymunk_mean_m']:.3f} m, batched {cell['batched_mean_m']:.3f} m)",
                      flush=True)
    cells = [c for c in store.cells() if c["scenario"] in names and c["episodes"] == args.episodes]
    print(table([c for c in cells if not c.get("draw", 0)]))
    more = replications(cells)
    if more:
        print("\nIndependent replications:\n" + more)


if __name__ == "__main__":
    main()
