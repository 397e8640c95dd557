"""The report of :mod:`benchmarks.rl_at_scale`: interquartile means with 95 % stratified-bootstrap intervals
(rliable), performance profiles and learning curves, from ``results/rl_at_scale/cells.jsonl`` and ``curves/``.

    python -m benchmarks.rl_at_scale_report [--out results/rl_at_scale] [--reps 2000]

A run's score is its final evaluation on the pymunk env (the reference world): the success rate over its
evaluation episodes, in [0, 1], and the mean final STL robustness (m). SB3's PPO is scored by its
deterministic policy (the Gaussian's mean, SB3's convention); MAPPO and IPPO by sampled actions, because
their TanhNormal policy flown at tanh of its mean is not the policy that was trained (its deterministic
score is reported beside it; :mod:`baselines.batched.marl`). Per scenario and
algorithm, the IQM over seeds of the success rate and of the robustness, with a 95 % bootstrap interval over
seeds; across scenarios, rliable's IQM, mean and optimality gap of the success rate with stratified-bootstrap
intervals (scenarios as tasks, seeds as runs; only the seeds that every scenario of the algorithm has, so that
the score matrix is rectangular). Every row states its env-step budget, the wall clock per run and the seeds.
Writes, each file atomically: ``summary.md`` (the tables), ``summary.json`` (the same numbers),
``curves_steps.png`` and ``curves_wall.png`` (learning curves against env-steps and against wall clock, one
panel a scenario, one line a seed: the reward per env-step of each rollout where the trainer logs it, without
the rollouts in which episodes end and restart, else the finished training episodes' success rate) and
``profile.png`` (the performance profile of the success rate). Needs rliable and matplotlib (the
``[rl-analysis]`` extra).
"""

from __future__ import annotations

import argparse
import json
import warnings
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np
from rliable import library as rly
from rliable import metrics

from impact_env.results_store import CellStore, atomic_path, write_atomic

RESULTS = Path(__file__).resolve().parents[1] / "results" / "rl_at_scale"
ALGORITHM_ORDER = ("sb3_ppo", "mappo", "ippo")
AGGREGATES = ("iqm", "mean", "optimality_gap")  # rliable's, across scenarios


def _key(cell: dict) -> tuple[str, str, int]:
    return (str(cell["algorithm"]), str(cell["task"]), int(cell["seed"]))


# how each algorithm's policy is flown for its score (module docstring)
POLICY_MODE = {"sb3_ppo": "deterministic", "mappo": "sampled", "ippo": "sampled"}


def scored_evaluation(cell: dict) -> tuple[str, dict]:
    """(policy mode, evaluation) that scores a run: its ``sampled`` evaluation where :data:`POLICY_MODE` asks
    for it and the run has one, else the deterministic one (the top level of ``evaluation``)."""
    evaluation = cell["evaluation"]
    if POLICY_MODE.get(str(cell["algorithm"])) == "sampled" and "sampled" in evaluation:
        return "sampled", evaluation["sampled"]
    return "deterministic", evaluation


def run_scores(cell: dict) -> tuple[float, float]:
    """(success rate, mean final robustness in m) of a run's scored evaluation on the reference world: the
    pymunk env for an impact task, VMAS itself for ``vmas/transport`` (no robustness: NaN)."""
    evaluation = scored_evaluation(cell)[1]
    ref = evaluation.get("pymunk", evaluation)
    return float(ref["success_rate"]), float(ref.get("robustness_mean", float("nan")))


def _order(algorithms: set[str]) -> list[str]:
    return [a for a in ALGORITHM_ORDER if a in algorithms] + sorted(algorithms - set(ALGORITHM_ORDER))


def _interval_estimates(scores: dict[str, np.ndarray], fn: Any, reps: int, seed: int) -> tuple[dict, dict]:
    """rliable's stratified bootstrap, seeded (a RandomState, which arch 7 warns it will stop taking)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        return rly.get_interval_estimates(scores, fn, reps=reps, random_state=np.random.RandomState(seed))


def iqm_interval(values: np.ndarray, reps: int, seed: int = 0) -> tuple[float, float, float]:
    """IQM of one task's runs and its 95 % bootstrap interval (rliable, a single stratum)."""
    scores = {"x": np.asarray(values, dtype=float).reshape(-1, 1)}
    point, interval = _interval_estimates(scores, lambda x: np.array([metrics.aggregate_iqm(x)]), reps, seed)
    return float(point["x"][0]), float(interval["x"][0, 0]), float(interval["x"][1, 0])


def aggregate(cells: list[dict], reps: int = 2000, seed: int = 0) -> dict[str, Any]:
    """The numbers of the report (module docstring) from the cells."""
    by: dict[tuple[str, str], list[dict]] = defaultdict(list)
    for cell in cells:
        by[(cell["algorithm"], cell["task"])].append(cell)
    rows = []
    for (algorithm, task), group in sorted(by.items(), key=lambda kv: (kv[0][1], _order({c[0] for c in by})
                                                                       .index(kv[0][0]))):
        group = sorted(group, key=lambda c: c["seed"])
        success = np.array([run_scores(c)[0] for c in group])
        robustness = np.array([run_scores(c)[1] for c in group])
        batched = [scored_evaluation(c)[1].get("batched", {}).get("success_rate") for c in group]
        deterministic = [c["evaluation"].get("pymunk", c["evaluation"])["success_rate"] for c in group]
        s_iqm, s_lo, s_hi = iqm_interval(success, reps, seed)
        finite = robustness[np.isfinite(robustness)]
        r_iqm, r_lo, r_hi = iqm_interval(finite, reps, seed) if finite.size else (float("nan"),) * 3
        rows.append({"algorithm": algorithm, "task": task, "seeds": [int(c["seed"]) for c in group],
                     "budget_env_steps": sorted({int(c["budget_env_steps"]) for c in group}),
                     "env_steps": [int(c["env_steps"]) for c in group],
                     "wall_s": [float(c["wall_s"]) for c in group],
                     "env_steps_per_s": [float(c["env_steps_per_s"]) for c in group],
                     "eval_episodes": sorted({int(c["evaluation"]["episodes"]) for c in group}),
                     "success": success.tolist(), "success_iqm": s_iqm, "success_ci": [s_lo, s_hi],
                     "batched_success": [None if b is None else float(b) for b in batched],
                     "policy": sorted({scored_evaluation(c)[0] for c in group}),
                     "deterministic_success": [float(d) for d in deterministic],
                     "robustness": robustness.tolist(), "robustness_iqm": r_iqm, "robustness_ci": [r_lo, r_hi]})
    overall = []
    for algorithm in _order({c["algorithm"] for c in cells}):
        tasks = sorted({c["task"] for c in cells if c["algorithm"] == algorithm and not c["task"].startswith("vmas/")})
        if not tasks:
            continue
        seeds_of = [{c["seed"] for c in cells if c["algorithm"] == algorithm and c["task"] == t} for t in tasks]
        seeds = sorted(set.intersection(*seeds_of))
        if not seeds:
            continue
        score = {(c["task"], c["seed"]): run_scores(c)[0] for c in cells if c["algorithm"] == algorithm}
        matrix = np.array([[score[(t, s)] for t in tasks] for s in seeds])  # [runs, tasks]
        point, interval = _interval_estimates(
            {algorithm: matrix}, lambda x: np.array([metrics.aggregate_iqm(x), metrics.aggregate_mean(x),
                                                     metrics.aggregate_optimality_gap(x)]), reps, seed)
        cells_used = [c for c in cells if c["algorithm"] == algorithm and c["task"] in tasks and c["seed"] in seeds]
        overall.append({"algorithm": algorithm, "tasks": tasks, "seeds": seeds, "matrix": matrix.tolist(),
                        "budget_env_steps": sorted({int(c["budget_env_steps"]) for c in cells_used}),
                        "wall_s_total": round(sum(float(c["wall_s"]) for c in cells_used), 1),
                        **{name: float(point[algorithm][i]) for i, name in enumerate(AGGREGATES)},
                        **{f"{name}_ci": [float(interval[algorithm][0, i]), float(interval[algorithm][1, i])]
                           for i, name in enumerate(AGGREGATES)}})
    pairs = [(e["batched"]["success_rate"], e["pymunk"]["success_rate"], int(c["evaluation"]["episodes"]), c["run"])
             for c in cells for e in [scored_evaluation(c)[1]] if "batched" in e and "pymunk" in e]
    gaps = [(abs(b - p), run) for b, p, _, run in pairs]
    transfer = None if not gaps else {"runs": len(gaps), "mean_abs_points": 100 * float(np.mean([g for g, _ in gaps])),
                                      "max_abs_points": 100 * max(gaps)[0], "max_run": max(gaps)[1],
                                      "within_5_points": sum(g <= 0.05 + 1e-12 for g, _ in gaps),
                                      "differ_at_0_01": [run for b, p, n, run in pairs if success_differ(b, p, n)]}
    return {"rows": rows, "overall": overall, "transfer": transfer, "reps": reps}


def _fmt_ci(point: float, ci: list[float], scale: float = 1.0, digits: int = 0, sign: str = "") -> str:
    if not np.isfinite(point):
        return "-"
    f = f"{{:{sign}.{digits}f}}"
    return f"{f.format(point * scale)} [{f.format(ci[0] * scale)}, {f.format(ci[1] * scale)}]"


def _steps(n: float) -> str:
    return f"{n / 1e6:g}M" if n >= 1e6 else f"{n / 1e3:g}k"


def markdown(numbers: dict[str, Any]) -> str:
    """``summary.md``: the overall IQM table, then per scenario and algorithm."""
    lines = ["Final evaluation on the pymunk env (the reference world) of policies trained on the "
             "batched world; interquartile means (IQM) with 95 % bootstrap intervals (rliable, "
             f"{numbers['reps']} resamples). Made by `python -m benchmarks.rl_at_scale --publish`.", ""]
    if numbers["overall"]:
        lines += ["## Across scenarios (success rate, %; stratified bootstrap over seeds within scenarios)", "",
                  "| algorithm | scenarios | seeds | budget (env-steps per run) | wall clock (all runs) | IQM | mean | "
                  "optimality gap |", "|---|---:|---|---:|---:|---:|---:|---:|"]
        for o in numbers["overall"]:
            lines.append(f"| {o['algorithm']} | {len(o['tasks'])} | {','.join(map(str, o['seeds']))} | "
                         f"{', '.join(_steps(b) for b in o['budget_env_steps'])} | {o['wall_s_total'] / 3600:.2f} h | "
                         f"{_fmt_ci(o['iqm'], o['iqm_ci'], 100)} | {_fmt_ci(o['mean'], o['mean_ci'], 100)} | "
                         f"{_fmt_ci(o['optimality_gap'], o['optimality_gap_ci'], 100)} |")
        lines.append("")
    lines += ["## Per scenario (IQM over seeds, 95 % bootstrap interval over seeds)", "",
              "| scenario | algorithm | seeds | budget (env-steps) | wall clock per run (min) | env-steps/s | "
              "eval episodes | policy | success % (pymunk) | success % per seed | batched-world success % per seed | "
              "deterministic success % per seed | robustness (m) |",
              "|---|---|---|---:|---:|---:|---:|---|---:|---|---|---|---:|"]
    for r in numbers["rows"]:
        per_seed = " / ".join(f"{100 * s:.0f}" for s in r["success"])
        batched = " / ".join("-" if b is None else f"{100 * b:.0f}" for b in r["batched_success"])
        deterministic = " / ".join(f"{100 * d:.0f}" for d in r.get("deterministic_success", []))
        lines.append(f"| {r['task']} | {r['algorithm']} | {','.join(map(str, r['seeds']))} | "
                     f"{', '.join(_steps(b) for b in r['budget_env_steps'])} | "
                     f"{np.mean(r['wall_s']) / 60:.1f} | {np.mean(r['env_steps_per_s']):,.0f} | "
                     f"{', '.join(map(str, r['eval_episodes']))} | {', '.join(r.get('policy', []))} | "
                     f"{_fmt_ci(r['success_iqm'], r['success_ci'], 100)} | {per_seed} | {batched} | {deterministic} | "
                     f"{_fmt_ci(r['robustness_iqm'], r['robustness_ci'], 1, 3, '+')} |")
    t = numbers.get("transfer")
    if t:
        lines += ["", f"Batched world against pymunk env, the same policy and seeds: the success rates differ by "
                  f"{t['mean_abs_points']:.1f} points on average over {t['runs']} runs, at most "
                  f"{t['max_abs_points']:.0f} ({t['max_run']}); {t['within_5_points']} of {t['runs']} runs within "
                  "5 points. The two worlds draw their noise from different generators, so each rate is a sample of "
                  "its own: by Fisher's exact test on the successes out of the episodes flown, "
                  f"{len(t['differ_at_0_01'])} of {t['runs']} runs differ at alpha 0.01"
                  f"{' (' + ', '.join(t['differ_at_0_01']) + ')' if t['differ_at_0_01'] else ''}."]
    lines += ["", "Each run's evaluation: the policy flown as `policy` says (SB3: its deterministic mean action; "
              "MAPPO, IPPO: sampled actions, as their TanhNormal policy was trained; their deterministic score is "
              "the column beside), `eval episodes` seeded episodes per world (seeds "
              "1,000,000 on), with the training's noise (thrust 5 %, objects start within 5 cm). The wall clock is "
              "training only (the evaluation is not in it), on the shared 2-core machine, one torch thread a run, "
              "one or two runs at a time (What ran says which)."]
    return "\n".join(lines) + "\n"


def success_differ(rate_a: float, rate_b: float, episodes: int, alpha: float = 0.01) -> bool:
    """Whether two success rates, each of ``episodes`` episodes, differ at ``alpha`` (two-sided Fisher exact
    test on the successes and failures)."""
    from scipy.stats import fisher_exact

    wins = [round(rate * episodes) for rate in (rate_a, rate_b)]
    return bool(fisher_exact([[w, episodes - w] for w in wins])[1] < alpha)


def _curves(out: Path) -> dict[str, list[dict]]:
    curves = {}
    for path in sorted((out / "curves").glob("*.jsonl")):
        rows = [json.loads(line) for line in path.read_text(encoding="utf-8").splitlines() if line.strip()]
        if rows:
            curves[path.stem] = rows
    return curves


def _curve_field(runs: list[list[dict]]) -> str:
    """What a panel's curves show: the reward per env-step where the trainer logs it (every rollout has one),
    else the training episodes' success rate, else their mean return (VMAS)."""
    for field in ("reward_per_step", "success_rate", "return_mean"):
        if any(r.get(field) is not None for run in runs for r in run):
            return field
    return "return_mean"


LABELS = {"reward_per_step": "reward per env-step", "success_rate": "training success rate",
          "return_mean": "training episode return"}


def plot_curves(curves: dict[str, list[dict]], x: str, path: Path) -> Path | None:
    """Learning curves against ``x`` (``frames`` or ``wall_s``), one panel a task (:func:`_curve_field`)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    by_task: dict[str, dict[str, list[list[dict]]]] = defaultdict(lambda: defaultdict(list))
    for name, rows in curves.items():
        algorithm, task, _ = name.split("__")
        by_task[task][algorithm].append(rows)
    if not by_task:
        return None
    tasks = sorted(by_task)
    cols = min(4, len(tasks))
    rows_n = -(-len(tasks) // cols)
    fig, axes = plt.subplots(rows_n, cols, figsize=(4 * cols, 3 * rows_n), squeeze=False)
    colours = {a: f"C{i}" for i, a in enumerate(_order({a for t in by_task.values() for a in t}))}
    for ax, task in zip(axes.flat, tasks):
        field = _curve_field([run for runs in by_task[task].values() for run in runs])
        for algorithm, runs in sorted(by_task[task].items()):
            for run in runs:
                # the reward of an episode's first step is the shaping's jump from zero: the rollouts where
                # episodes end (and start) and the first rollout are left out of the reward-per-step curve
                keep = run[1:] if field == "reward_per_step" else run
                pts = [(r[x], r[field]) for r in keep if r.get(field) is not None
                       and not (field == "reward_per_step" and r.get("episodes"))]
                if pts:
                    xs, ys = zip(*pts)
                    ax.plot(np.array(xs) / (1e6 if x == "frames" else 60), ys, color=colours[algorithm], alpha=0.6,
                            lw=0.9)
            ax.plot([], [], color=colours[algorithm], label=f"{algorithm} ({len(runs)} seeds)")
        ax.set_title(task, fontsize=9)
        ax.set_xlabel("env-steps (M)" if x == "frames" else "wall clock (min)")
        ax.set_ylabel(LABELS[field], fontsize=8)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    for ax in list(axes.flat)[len(tasks):]:
        ax.axis("off")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=90)
    plt.close(fig)
    return path


def plot_profile(numbers: dict[str, Any], path: Path, reps: int) -> Path | None:
    """rliable's performance profile of the per-run success rates (runs x scenarios), one line per algorithm."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if not numbers["overall"]:
        return None
    scores = {o["algorithm"]: np.array(o["matrix"]) for o in numbers["overall"]}
    taus = np.linspace(0.0, 1.0, 51)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        np.random.seed(0)  # the profile's bootstrap takes no generator; arch draws from numpy's global one
        dist, dist_ci = rly.create_performance_profile(scores, taus, reps=reps)
    fig, ax = plt.subplots(figsize=(5, 3.5))
    for i, (algorithm, d) in enumerate(dist.items()):
        ax.plot(taus, d, color=f"C{i}", label=algorithm)
        ax.fill_between(taus, dist_ci[algorithm][0], dist_ci[algorithm][1], color=f"C{i}", alpha=0.2)
    ax.set_xlabel("success rate tau (pymunk evaluation)")
    ax.set_ylabel("fraction of runs with success > tau")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=90)
    plt.close(fig)
    return path


def write_report(out: Path = RESULTS, reps: int = 2000) -> dict[str, Any]:
    """Write the report's files into ``out`` (module docstring); returns its numbers."""
    cells = CellStore(out / "cells.jsonl", _key).cells()
    numbers = aggregate(cells, reps)
    write_atomic(out / "summary.json", json.dumps(numbers, indent=1))
    write_atomic(out / "summary.md", markdown(numbers))
    curves = _curves(out)
    plot_curves(curves, "frames", out / "curves_steps.png")
    plot_curves(curves, "wall_s", out / "curves_wall.png")
    plot_profile(numbers, out / "profile.png", reps)
    return numbers


DOCS_BEGIN, DOCS_END = "<!-- results: made by python -m benchmarks.rl_at_scale_report --docs -->", "<!-- /results -->"


def write_docs(out: Path, page: Path, images: Path, status: str = "") -> Path:
    """Copy the report's tables (``summary.md``, its headings one level down) and figures into a docs page,
    between its results markers (or in place of ``<!-- results -->``), and the figures into ``images``."""
    for name in ("curves_steps.png", "curves_wall.png", "profile.png"):
        if (out / name).exists():
            write_atomic(images / name, (out / name).read_bytes())
    rel = images.relative_to(page.parent)
    body = (out / "summary.md").read_text(encoding="utf-8").replace("\n## ", "\n### ")
    figures = "\n".join(f"![{alt}]({rel / name})" for name, alt in (
        ("curves_steps.png", "learning curves against env-steps"), ("curves_wall.png", "learning curves against "
         "wall clock"), ("profile.png", "performance profile of the success rate")) if (images / name).exists())
    block = f"{DOCS_BEGIN}\n## Results\n\n{status}{body}\n{figures}\n{DOCS_END}"
    text = page.read_text(encoding="utf-8")
    if DOCS_BEGIN in text:
        text = text[:text.index(DOCS_BEGIN)] + block + text[text.index(DOCS_END) + len(DOCS_END):]
    else:
        text = text.replace("<!-- results -->", block)
    return write_atomic(page, text)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=RESULTS)
    parser.add_argument("--reps", type=int, default=2000, help="bootstrap resamples")
    parser.add_argument("--docs", action="store_true", help="also copy the tables and figures into "
                        "docs/rl_at_scale.md and docs/img/rl_at_scale/")
    parser.add_argument("--status", type=Path, default=None, help="--docs: a markdown file whose text goes first "
                        "(what ran, what remains)")
    args = parser.parse_args(argv)
    numbers = write_report(args.out, args.reps)
    if args.docs:
        docs = Path(__file__).resolve().parents[1] / "docs"
        status = args.status.read_text(encoding="utf-8") + "\n" if args.status else ""
        write_docs(args.out, docs / "rl_at_scale.md", docs / "img" / "rl_at_scale", status)
    print(markdown(numbers))


if __name__ == "__main__":
    main()
