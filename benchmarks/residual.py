"""The residual policy on top of the expert against the expert alone, on the same seeded episodes.

    python -m benchmarks.residual --scenarios narrow_gap,timed_visits --train-seeds 0     # needs the runs
    python -m benchmarks.residual --table-only

For each scenario the expert (stack ``all``, the robustness benchmark's cached plan, results/robustness/plans)
flies ``--seeds`` episodes (env seeds ``--first-seed`` ...) under the residual's training condition
(:data:`baselines.residual.TRAINING_NOISE`: 0.02 m/s post-impact velocity noise, 5 % thrust noise, 5 cm start
noise), alone and with each trained residual (``results/residual/runs/residual_<scenario>_s<seed>``,
``impact-env residual``,
whose training episodes use other env seeds). The seeds are shared, so the start, the thrust noise and the
impact noise draws are the same until the correction changes what happens.

Per scenario and run: successes of the expert alone and with the residual out of the same episodes, robustness
means, the paired comparison: McNemar's exact test (the episodes only one of the two succeeds in: two-sided
binomial p, and one-sided for "the residual succeeds more often"), and a paired bootstrap 95 % interval of the
difference in success rate and in mean robustness; over training seeds (3 or more), rliable's IQM with its
95 % bootstrap interval. Each (scenario, controller, training seed) is a cell of ``--out``/cells.jsonl, written
when done (resumable, :mod:`impact_env.results_store`); the table goes to ``--out``/table.md.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from impact_env.results_store import CellStore, write_atomic

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "results" / "residual"
PLANS = ROOT / "results" / "robustness" / "plans"
STACK = "all"
MIN_SEEDS = 3  # rliable's interval over fewer training seeds says little


def store(out: Path) -> CellStore:
    return CellStore(out / "cells.jsonl", key=lambda c: (c["scenario"], c["controller"], c["train_seed"]))


def expert_config_now() -> str:
    """The fingerprint of the expert's config as it is now (the robustness benchmark's, of stack ``all``): a cell
    records the one it was flown with (``config``)."""
    from benchmarks.robustness import config_fingerprint

    return config_fingerprint(STACK)


def current(cell: dict | None) -> bool:
    """True if ``cell`` was flown with today's expert config (:data:`benchmarks.robustness.SAME_FLIGHTS` counted);
    a cell from before cells recorded it is not: the expert it paired with may have changed since."""
    from benchmarks.robustness import same_flights

    return cell is not None and same_flights(cell.get("config")) == expert_config_now()


def fly_cell(scenario_name: str, run_dir: Path | None, seeds: list[int], plan: Path) -> dict[str, Any]:
    """The episodes of one controller: the expert alone (``run_dir`` None) or with the residual of ``run_dir``."""
    from baselines.residual import TRAINING_NOISE, ResidualController, build_expert
    from impact_env.rollout import run_episode
    from impact_env.transport.gym_env import TransportEnv
    from impact_env.transport.scenario import load_scenario

    scenario = load_scenario(scenario_name)
    expert = build_expert(scenario, str(plan), STACK)
    controller: Any = expert if run_dir is None else ResidualController(expert, run_dir)
    options: dict[str, Any] = dict(TRAINING_NOISE)
    env = TransportEnv(scenario, **options)
    episodes = []
    start = time.perf_counter()
    for seed in seeds:
        result = run_episode(env, controller, seed=seed)
        row = {"seed": seed, "success": bool(result.success), "robustness": float(result.robustness),
               "ms_per_step": float(np.median(result.controller_ms))}
        if run_dir is not None:
            row["residual_rms"] = float(np.sqrt(np.mean(np.square(controller.residuals))))
        episodes.append(row)
    env.close()
    return {"wall_s": time.perf_counter() - start, "episodes": episodes}


def mcnemar(expert: np.ndarray, residual: np.ndarray) -> dict[str, Any]:
    """McNemar's exact test on paired successes: b episodes only the residual succeeds in, c only the expert;
    two-sided p = P(|binomial(b + c, 1/2) - (b+c)/2| >= |b - (b+c)/2|), one-sided p = P(binomial >= b)."""
    from scipy.stats import binomtest

    b = int(np.sum(residual & ~expert))
    c = int(np.sum(expert & ~residual))
    if b + c == 0:
        return {"only_residual": 0, "only_expert": 0, "p_two_sided": 1.0, "p_residual_better": 1.0}
    return {"only_residual": b, "only_expert": c,
            "p_two_sided": float(binomtest(b, b + c, 0.5).pvalue),
            "p_residual_better": float(binomtest(b, b + c, 0.5, alternative="greater").pvalue)}


def paired_interval(diff: np.ndarray, reps: int = 10_000, seed: int = 0) -> tuple[float, float]:
    """95 % percentile bootstrap interval of the mean of paired differences (episodes resampled together)."""
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, len(diff), size=(reps, len(diff)))
    means = diff[idx].mean(axis=1)
    return float(np.percentile(means, 2.5)), float(np.percentile(means, 97.5))


def compare(expert_cell: dict, residual_cell: dict) -> dict[str, Any]:
    """The paired comparison of the same seeds (see the module docstring)."""
    e = {r["seed"]: r for r in expert_cell["episodes"]}
    rows = [(e[r["seed"]], r) for r in residual_cell["episodes"] if r["seed"] in e]
    es = np.array([a["success"] for a, _ in rows])
    rs = np.array([b["success"] for _, b in rows])
    er = np.array([a["robustness"] for a, _ in rows])
    rr = np.array([b["robustness"] for _, b in rows])
    return {"episodes": len(rows), "expert_successes": int(es.sum()), "residual_successes": int(rs.sum()),
            "expert_robustness": float(er.mean()), "residual_robustness": float(rr.mean()),
            "success_diff_ci": paired_interval(rs.astype(float) - es.astype(float)),
            "robustness_diff_ci": paired_interval(rr - er),
            "residual_rms": float(np.mean([b.get("residual_rms", np.nan) for _, b in rows])),
            **mcnemar(es, rs)}


def _run_meta(run_dir: Path) -> dict[str, Any]:
    path = run_dir / "train.json"
    return json.loads(path.read_text()) if path.is_file() else {}


def table(out: Path) -> str:
    """The markdown table of every scenario with an expert cell and at least one residual cell."""
    cells = store(out)
    scenarios = sorted({c["scenario"] for c in cells if c["controller"] == "residual"})
    lines = ["| scenario | training seed | env-steps | training wall clock | episodes | expert successes | "
             "expert + residual successes | only residual / only expert | McNemar p (two-sided; residual better) | "
             "success difference [95 % CI] | robustness expert / + residual (m) | robustness difference [95 % CI] | "
             "RMS correction |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    over_seeds = []
    stale = False
    for name in scenarios:
        expert = cells.get((name, "expert", -1))
        if expert is None:
            continue
        old_expert = not current(expert)
        residuals = sorted((c for c in cells if c["scenario"] == name and c["controller"] == "residual"),
                           key=lambda c: c["train_seed"])
        diffs = []
        for cell in residuals:
            cmp = compare(expert, cell)
            diffs.append(cmp["residual_successes"] - cmp["expert_successes"])
            lo, hi = cmp["success_diff_ci"]
            rlo, rhi = cmp["robustness_diff_ci"]
            n = cmp["episodes"]
            mark = " *" if old_expert or not current(cell) else ""
            stale = stale or bool(mark)
            lines.append(
                f"| {name}{mark} | {cell['train_seed']} | {cell['train_env_steps']:,} | "
                f"{cell['train_wall_s'] / 60:.1f} min | {n} | {cmp['expert_successes']} | "
                f"{cmp['residual_successes']} | {cmp['only_residual']} / "
                f"{cmp['only_expert']} | {cmp['p_two_sided']:.3f}; {cmp['p_residual_better']:.3f} | "
                f"{100 * (cmp['residual_successes'] - cmp['expert_successes']) / n:+.0f} pp "
                f"[{100 * lo:+.0f}, {100 * hi:+.0f}] | {cmp['expert_robustness']:+.3f} / "
                f"{cmp['residual_robustness']:+.3f} | {cmp['residual_robustness'] - cmp['expert_robustness']:+.3f} "
                f"[{rlo:+.3f}, {rhi:+.3f}] | {cmp['residual_rms']:.3f} |")
        if len(diffs) >= MIN_SEEDS:
            from benchmarks.rl_at_scale_report import iqm_interval

            point, lo, hi = iqm_interval(np.array(diffs, float), reps=2000)
            over_seeds.append(f"- {name}: IQM over {len(diffs)} training seeds of (residual - expert) successes "
                              f"{point:+.1f} [{lo:+.1f}, {hi:+.1f}] (rliable, 95 % bootstrap)")
    text = "\n".join(lines)
    if over_seeds:
        text += "\n\n" + "\n".join(over_seeds)
    experts = sorted((c for c in cells if c["controller"] == "expert"), key=lambda c: c["scenario"])
    text += ("\n\nThe expert alone (stack all), every scenario flown:\n\n| scenario | episodes | successes | "
             "robustness mean (min) m | controller ms per step (median) |\n|---|---:|---:|---:|---:|\n")
    text += "\n".join(f"| {c['scenario']}{'' if current(c) else ' *'} | {len(c['episodes'])} | "
                      f"{sum(e['success'] for e in c['episodes'])} | "
                      f"{np.mean([e['robustness'] for e in c['episodes']]):+.3f} "
                      f"({min(e['robustness'] for e in c['episodes']):+.3f}) | "
                      f"{np.median([e['ms_per_step'] for e in c['episodes']]):.2f} |" for c in experts)
    if stale or any(not current(c) for c in experts):
        text += ("\n\n\\* flown with an earlier expert (another config, or from before cells recorded it): not "
                 "a comparison with today's expert; `python -m benchmarks.residual --scenarios NAME --train-seeds "
                 "S` flies it again")
    return text


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenarios", default="", help="comma-separated scenario names")
    ap.add_argument("--train-seeds", default="0", help="comma-separated training seeds of the residual runs")
    ap.add_argument("--runs-dir", type=Path, default=RESULTS / "runs",
                    help="where the run folders residual_<scenario>_s<seed> are (default results/residual/runs)")
    ap.add_argument("--seeds", type=int, default=50, help="episodes per controller (default 50)")
    ap.add_argument("--first-seed", type=int, default=0, help="env seed of the first episode (default 0)")
    ap.add_argument("--out", type=Path, default=RESULTS, help="cells.jsonl and table.md (default results/residual)")
    ap.add_argument("--expert-only", action="store_true", help="fly only the expert's cells")
    ap.add_argument("--table-only", action="store_true", help="only rewrite the table from the cells")
    args = ap.parse_args(argv)
    if args.seeds < 1:
        ap.error(f"--seeds must be >= 1, got {args.seeds}")
    try:
        train_seeds = [int(s) for s in args.train_seeds.split(",") if s]
    except ValueError:
        ap.error(f"--train-seeds must be comma-separated integers, got {args.train_seeds!r}")
    args.out.mkdir(parents=True, exist_ok=True)
    cells = store(args.out)
    seeds = list(range(args.first_seed, args.first_seed + args.seeds))
    for name in ([] if args.table_only else [s for s in args.scenarios.split(",") if s]):
        plan = PLANS / f"{name}.json"
        if not plan.is_file():
            ap.error(f"no cached plan {plan}: run python -m benchmarks.robustness --scenarios {name} first")
        if not current(cells.get((name, "expert", -1))):
            cell = fly_cell(name, None, seeds, plan)
            cells.put({"scenario": name, "controller": "expert", "train_seed": -1, "stack": STACK, "seeds": seeds,
                       "config": expert_config_now(), **cell})
            n = sum(e["success"] for e in cell["episodes"])
            print(f"{name}: expert alone {n}/{len(seeds)} ({cell['wall_s']:.0f} s)", flush=True)
        for train_seed in ([] if args.expert_only else train_seeds):
            run_dir = args.runs_dir / f"residual_{name}_s{train_seed}"
            meta = _run_meta(run_dir)
            if not meta:
                print(f"{name}: no residual run in {run_dir} (impact-env residual {name} --plan {plan} "
                      f"--seed {train_seed} --out {run_dir}); skipped", flush=True)
                continue
            done = cells.get((name, "residual", train_seed))
            if done is not None and done["train_env_steps"] == meta["timesteps_trained"] and current(done):
                continue
            cell = fly_cell(name, run_dir, seeds, plan)
            cells.put({"scenario": name, "controller": "residual", "train_seed": train_seed, "run": str(run_dir),
                       "train_env_steps": int(meta["timesteps_trained"]), "train_wall_s": float(meta["wall_time_s"]),
                       "scale": meta["scale"], "stack": meta["stack"], "seeds": seeds, "config": expert_config_now(),
                       **cell})
            n = sum(e["success"] for e in cell["episodes"])
            print(f"{name}: expert + residual (seed {train_seed}, {meta['timesteps_trained']:,} env-steps) "
                  f"{n}/{len(seeds)} ({cell['wall_s']:.0f} s)", flush=True)
    text = table(args.out)
    write_atomic(args.out / "table.md", text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
