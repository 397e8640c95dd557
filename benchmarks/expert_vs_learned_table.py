"""The table of :mod:`benchmarks.expert_vs_learned`: per shipped scenario, the expert, SB3 PPO, MAPPO, IPPO and the
random controller on the same seeded pymunk episodes, then the same across scenarios.

The two kinds of row carry different statistics, and the table says which. A flown controller (expert, random)
is one controller on ``N`` episodes: its success rate with a 95 % Wilson score interval over the episodes, and
its mean final robustness with a 95 % percentile-bootstrap interval over the episodes. A learned algorithm is
several training runs (seeds), each evaluated on 50-100 of those episodes: the interquartile mean (IQM) over
seeds of the runs' success rates and mean robustness, with rliable's 95 % bootstrap interval over seeds, as
:func:`benchmarks.rl_at_scale_report.aggregate` computes them (SB3 scored by its deterministic policy, MAPPO
and IPPO by sampled actions, :data:`~benchmarks.rl_at_scale_report.POLICY_MODE`). Every learned row states its
env-step budget, the training wall clock per run and its seeds; a row with fewer than 3 seeds says so, and an
algorithm with no finished run on a scenario has a row that says that too. Writes ``summary.md`` and
``summary.json`` (the same numbers) atomically; :func:`write_docs` copies the tables into a docs page.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from impact_env.results_store import CellStore, write_atomic


def cell_key(cell: dict) -> tuple[str, str]:
    """A cell of ``results/expert_vs_learned/cells.jsonl`` is named by (controller, scenario)."""
    return (str(cell["controller"]), str(cell["scenario"]))

LEARNED = {"sb3_ppo": "SB3 PPO", "mappo": "MAPPO", "ippo": "IPPO"}  # algorithm -> its label, in the table's order
MIN_SEEDS = 3  # the bar for a learned row
Z95 = 1.959963984540054  # the standard normal's 97.5 % quantile
DOCS_BEGIN = "<!-- expert-vs-learned: made by python -m benchmarks.expert_vs_learned --publish --docs -->"
DOCS_END = "<!-- /expert-vs-learned -->"


def wilson_interval(successes: int, n: int, z: float = Z95) -> tuple[float, float]:
    """The Wilson score interval of a success rate of ``successes`` in ``n`` trials (95 % for the default z)."""
    if n < 1 or not 0 <= successes <= n:
        raise ValueError(f"need 0 <= successes <= n and n >= 1, got {successes} of {n}")
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z / (1 + z * z / n) * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return max(0.0, centre - half), min(1.0, centre + half)


def bootstrap_mean_interval(values: list[float], reps: int, seed: int = 0) -> tuple[float, float]:
    """95 % percentile-bootstrap interval of the mean of ``values`` (resampled with replacement, seeded)."""
    x = np.asarray(values, dtype=float)
    means = x[np.random.default_rng(seed).integers(0, x.size, size=(reps, x.size))].mean(axis=1)
    return float(np.percentile(means, 2.5)), float(np.percentile(means, 97.5))


def flown_row(cell: dict, reps: int) -> dict[str, Any]:
    """The row of an expert or random cell (module docstring)."""
    episodes = cell["episodes"]
    wins = sum(bool(e["success"]) for e in episodes)
    robustness = [float(e["robustness"]) for e in episodes]
    return {"scenario": cell["scenario"], "controller": cell["controller"], "kind": "flown",
            "episodes": len(episodes), "successes": wins, "success": wins / len(episodes),
            "success_ci": list(wilson_interval(wins, len(episodes))), "robustness": float(np.mean(robustness)),
            "robustness_ci": list(bootstrap_mean_interval(robustness, reps)),
            "first_seed": cell["first_seed"], "plan": cell.get("plan")}


def learned_row(row: dict[str, Any]) -> dict[str, Any]:
    """A row of :func:`benchmarks.rl_at_scale_report.aggregate`, as this table shows it."""
    return {"scenario": row["task"], "controller": LEARNED.get(row["algorithm"], row["algorithm"]),
            "algorithm": row["algorithm"], "kind": "learned", "seeds": row["seeds"],
            "success": row["success_iqm"], "success_ci": row["success_ci"], "success_per_seed": row["success"],
            "robustness": row["robustness_iqm"], "robustness_ci": row["robustness_ci"],
            "budget_env_steps": row["budget_env_steps"], "wall_s": row["wall_s"],
            "eval_episodes": row["eval_episodes"], "policy": row.get("policy", [])}


def numbers(flown: list[dict], learned: list[dict], scenarios: list[str], reps: int = 2000) -> dict[str, Any]:
    """The table's numbers from the expert/random cells and rl_at_scale's cells (other tasks left out)."""
    from benchmarks.rl_at_scale_report import aggregate

    learned = [c for c in learned if c["task"] in scenarios]
    report = aggregate(learned, reps)
    by_learned = {(r["task"], r["algorithm"]): learned_row(r) for r in report["rows"]}
    by_flown = {(c["scenario"], c["controller"]): flown_row(c, reps) for c in flown if c["scenario"] in scenarios}
    algorithms = list(LEARNED) + sorted({c["algorithm"] for c in learned} - set(LEARNED))
    rows = []
    for scenario in scenarios:
        rows += [by_flown[(scenario, "expert")]] if (scenario, "expert") in by_flown else []
        for algorithm in algorithms:
            rows.append(by_learned.get((scenario, algorithm), {"scenario": scenario, "kind": "missing",
                                                               "algorithm": algorithm,
                                                               "controller": LEARNED.get(algorithm, algorithm)}))
        rows += [by_flown[(scenario, "random")]] if (scenario, "random") in by_flown else []
    overall = []
    for controller in ("expert", "random"):
        cells = [c for c in flown if c["controller"] == controller and c["scenario"] in scenarios]
        if cells:
            wins = sum(bool(e["success"]) for c in cells for e in c["episodes"])
            n = sum(len(c["episodes"]) for c in cells)
            overall.append({"controller": controller, "kind": "flown",
                            "scenarios": sorted(c["scenario"] for c in cells), "episodes": n,
                            "mean": wins / n, "mean_ci": list(wilson_interval(wins, n))})
    for o in report["overall"]:
        overall.append({"controller": LEARNED.get(o["algorithm"], o["algorithm"]), "kind": "learned",
                        "scenarios": o["tasks"], "seeds": o["seeds"], "budget_env_steps": o["budget_env_steps"],
                        "wall_s_total": o["wall_s_total"], **{k: o[k] for k in ("iqm", "iqm_ci", "mean", "mean_ci")}})
    overall += [{"controller": label, "kind": "missing"} for algorithm, label in LEARNED.items()
                if algorithm not in {o["algorithm"] for o in report["overall"]}]
    order = ["expert", *LEARNED.values(), "random"]
    overall.sort(key=lambda o: order.index(o["controller"]) if o["controller"] in order else len(order))
    return {"scenarios": scenarios, "rows": rows, "overall": overall, "reps": reps}


def _interval(point: float, ci: list[float], scale: float = 100.0, digits: int = 0, sign: str = "") -> str:
    if point is None or not np.isfinite(point):
        return "-"
    f = f"{{:{sign}.{digits}f}}"
    return f"{f.format(point * scale)} [{f.format(ci[0] * scale)}, {f.format(ci[1] * scale)}]"


def _steps(budgets: list[int]) -> str:
    return ", ".join(f"{b / 1e6:g}M" if b >= 1e6 else f"{b / 1e3:g}k" for b in budgets)


def _minutes(wall_s: list[float]) -> str:
    mean = np.mean(wall_s) / 60
    return f"{mean:.1f}" if len(wall_s) == 1 else f"{mean:.1f} ({min(wall_s) / 60:.1f}-{max(wall_s) / 60:.1f})"


def _episodes(counts: list[int]) -> str:
    return str(counts[0]) if len(counts) == 1 else f"{min(counts)}-{max(counts)}"


def _row(r: dict[str, Any]) -> str:
    if r["kind"] == "missing":
        return f"| {r['scenario']} | {r['controller']} | no finished run | - | - | - | - | - |"
    if r["kind"] == "flown":
        return (f"| {r['scenario']} | {r['controller']} | {_interval(r['success'], r['success_ci'])} | "
                f"{_interval(r['robustness'], r['robustness_ci'], 1.0, 3, '+')} | {r['episodes']} episodes | "
                "- | - | - |")
    n = len(r["seeds"])
    few = f" (fewer than {MIN_SEEDS})" if n < MIN_SEEDS else ""
    return (f"| {r['scenario']} | {r['controller']} | {_interval(r['success'], r['success_ci'])} | "
            f"{_interval(r['robustness'], r['robustness_ci'], 1.0, 3, '+')} | {n} seed{'s' if n > 1 else ''}{few} x "
            f"{_episodes(r['eval_episodes'])} episodes, {', '.join(r['policy'])} | {_steps(r['budget_env_steps'])} | "
            f"{_minutes(r['wall_s'])} | {','.join(map(str, r['seeds']))} |")


def markdown(numbers: dict[str, Any]) -> str:
    """``summary.md``: across scenarios, then per scenario (module docstring)."""
    flown = sorted({r["episodes"] for r in numbers["rows"] if r["kind"] == "flown"})
    evaluated = sorted({n for r in numbers["rows"] if r["kind"] == "learned" for n in r["eval_episodes"]})
    lines = ["On the pymunk env with 5 % thrust noise and objects starting within 5 cm, episodes seeded 1,000,000 "
             "on, success = final STL robustness > 0. **expert, random**: one controller on the first "
             f"{_episodes(flown) if flown else 'N'} episodes, success % with a 95 % Wilson interval over them, "
             "mean robustness with a 95 % bootstrap interval over them. **SB3 PPO, MAPPO, IPPO**: trained on the "
             "batched world (`benchmarks.rl_at_scale`), one run a seed, each evaluated on the first "
             f"{_episodes(evaluated) if evaluated else 'N'} of the same episodes; the interquartile mean (IQM) over "
             "seeds of the runs' success rate and mean robustness, with a 95 % bootstrap interval over seeds (rliable, "
             f"{numbers['reps']} resamples). SB3 flies its deterministic policy, MAPPO and IPPO sampled actions. "
             "The wall clock is the training's, per run, on the shared 2-core machine. Made by "
             "`python -m benchmarks.expert_vs_learned --publish`.", ""]
    if numbers["overall"]:
        lines += ["## Across scenarios (success %)", "",
                  "| controller | scenarios | seeds | env-steps per run | training wall clock (all runs) | "
                  "IQM [95 % interval] | mean [95 % interval] |", "|---|---:|---|---:|---:|---:|---:|"]
        for o in numbers["overall"]:
            if o["kind"] == "missing":
                lines.append(f"| {o['controller']} | 0 | - | - | - | no finished run | - |")
            elif o["kind"] == "flown":
                lines.append(f"| {o['controller']} | {len(o['scenarios'])} | - | - | - | - | "
                             f"{_interval(o['mean'], o['mean_ci'])} ({o['episodes']} episodes, Wilson) |")
            else:
                lines.append(f"| {o['controller']} | {len(o['scenarios'])} | {','.join(map(str, o['seeds']))} | "
                             f"{_steps(o['budget_env_steps'])} | {o['wall_s_total'] / 3600:.2f} h | "
                             f"{_interval(o['iqm'], o['iqm_ci'])} | {_interval(o['mean'], o['mean_ci'])} |")
        lines += ["", "A learned row across scenarios takes the seeds that every one of its scenarios has (rliable's "
                  "stratified bootstrap needs a full matrix of runs x scenarios).", ""]
    lines += ["## Per scenario", "",
              "| scenario | controller | success % [95 % interval] | robustness (m) [95 % interval] | over | "
              "env-steps per run | training wall clock per run (min) | seeds |",
              "|---|---|---:|---:|---|---:|---:|---|"]
    lines += [_row(r) for r in numbers["rows"]]
    return "\n".join(lines) + "\n"


def write_summary(out: Path, learned: Path, reps: int = 2000) -> str:
    """``out``/summary.md and summary.json from ``out``/cells.jsonl and the learned cells at ``learned`` (either
    may be missing); returns the markdown."""
    from benchmarks.rl_at_scale import SCENARIOS
    from benchmarks.rl_at_scale import cell_key as learned_key

    flown = CellStore(out / "cells.jsonl", cell_key).cells()
    runs = CellStore(learned, learned_key).cells()
    table = numbers(flown, runs, list(SCENARIOS), reps)
    write_atomic(out / "summary.json", json.dumps(table, indent=1))
    text = markdown(table)
    write_atomic(out / "summary.md", text)
    return text


def write_docs(out: Path, page: Path) -> Path:
    """Put ``out``/summary.md (its headings one level down) into ``page``, between its expert-vs-learned markers."""
    text = page.read_text(encoding="utf-8")
    if DOCS_BEGIN not in text or DOCS_END not in text:
        raise SystemExit(f"{page} has no {DOCS_BEGIN} ... {DOCS_END} markers: add them where the table goes")
    body = (out / "summary.md").read_text(encoding="utf-8").replace("\n## ", "\n### ")
    block = f"{DOCS_BEGIN}\n{body}{DOCS_END}"
    return write_atomic(page, text[:text.index(DOCS_BEGIN)] + block + text[text.index(DOCS_END) + len(DOCS_END):])
