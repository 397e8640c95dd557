"""BC against DAgger on the same budget of expert-labelled episodes: ``python -m benchmarks.dagger``.

For each scenario, budget and seed, both methods get that many episodes labelled by the expert
(``--budgets``; every step of them: the budget is also their env steps), under 5 % thrust noise and 5 cm
start noise, flying the committed spatially robust plan of ``results/robustness/plans/``:

- BC: the expert flies all of them and a policy is fitted once (``impact-env dagger --rounds 0``: the fit of
  ``impact-env bc``, :func:`baselines.bc.fit_policy`);
- DAgger: the expert flies the first ``--initial-share`` of the same episodes, then ``--rounds`` rounds label
  the mixed policy's episodes, ``(budget - initial) / rounds`` each (:mod:`baselines.dagger`).

Each policy flies ``--eval-episodes`` episodes alone (the same env seeds for every cell; DAgger's after every
round). Reported per scenario and method: success over the seeds' evaluation episodes with a 95 % Wilson
interval and each seed's rate, mean robustness, env steps, labels that needed an expert re-plan (count and
the seconds those labels took), labelling seconds, and wall clock per seed (data collection and fits, without
the evaluations); and per DAgger round, the means over seeds. Cells (scenario, budget, method, seed) go to
``results/dagger/cells.jsonl`` as they finish, runs to ``runs/dagger_bench/``; a rerun skips finished cells.

    nice -n 5 python -m benchmarks.dagger [--scenarios throw_and_catch_exp,corridor] [--seeds 0,1,2] [--budgets 6,12]
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path
from typing import Any

OUT = Path("results/dagger")
RUNS = Path("runs/dagger_bench")
PLANS = Path("results/robustness/plans")
NOISE = {"thrust_noise": 0.05, "initial_position_noise_m": 0.05}
METHODS = ("bc", "dagger")


def _store():
    from impact_env.results_store import CellStore

    return CellStore(OUT / "cells.jsonl", key=_key)


def _key(cell: dict) -> tuple:
    """(scenario, budget, method, seed, validation episodes DAgger selects its round on; 0: the last round)."""
    return (cell["scenario"], cell["budget_episodes"], cell["method"], cell["seed"], cell.get("select_episodes", 0))


def _final(cell: dict) -> dict:
    """The row of the round the cell's run returned (the selected one, else the last)."""
    return cell["rows"][cell.get("selected_round", len(cell["rows"]) - 1)]


def run_cell(scenario: str, budget: int, method: str, seed: int, args: argparse.Namespace) -> dict[str, Any]:
    import json

    from baselines.dagger import DAggerConfig, dagger

    initial = max(1, round(args.initial_share * budget))
    per_round = (budget - initial) // args.rounds
    select = args.select_episodes if method == "dagger" else 0
    config = DAggerConfig(
        scenario, rounds=0 if method == "bc" else args.rounds,
        initial_episodes=budget if method == "bc" else initial, episodes_per_round=per_round,
        beta_decay=args.beta_decay, eval_episodes=args.eval_episodes, select_episodes=select,
        plan=str(PLANS / f"{scenario}.json"), env_options=NOISE, epochs=args.epochs, seed=seed,
        out=str(RUNS / (f"{method}_{scenario}_b{budget}_s{seed}" + (f"_select{select}" if select else ""))),
        resume=True, quiet=False)
    start = time.perf_counter()
    run = dagger(config)
    state = json.loads((run / "dagger.json").read_text())
    rows = state["rounds"]
    return {"scenario": scenario, "method": method, "seed": seed, "budget_episodes": budget,
            "select_episodes": select, "selected_round": state.get("selected_round", len(rows) - 1),
            "initial_episodes": config.initial_episodes, "rounds": config.rounds, "episodes_per_round": per_round,
            "beta_decay": config.beta_decay, "epochs": config.epochs, "env_options": NOISE,
            "eval_episodes": config.eval_episodes, "run": str(run), "rows": rows,
            "cell_wall_s": time.perf_counter() - start}


def _sum(rows: list[dict], key: str) -> float:
    return sum(r[key] or 0 for r in rows)


def table() -> str:
    from benchmarks.expert_vs_learned_table import wilson_interval

    cells = list(_store())
    lines = ["| scenario | method | expert-labelled episodes (env steps) | success % (95 % CI) | per seed % | "
             "robustness m (mean) | labels that needed a re-plan (of labels) | episodes out of re-plans | "
             "their seconds / labelling s | wall clock s per seed |", "|" + "---|" * 10]
    rounds_lines = ["| scenario | budget | round | beta | data set labels | labels that needed a re-plan | "
                    "their seconds | learner's error on its own states | validation error | learner's success % |",
                    "|" + "---|" * 10]
    for scenario, budget in dict.fromkeys((c["scenario"], c["budget_episodes"]) for c in cells):
        variants = sorted({(c["method"], c.get("select_episodes", 0)) for c in cells
                           if c["scenario"] == scenario and c["budget_episodes"] == budget},
                          key=lambda v: (METHODS.index(v[0]), v[1]))
        for method, select in variants:
            mine = sorted((c for c in cells if c["scenario"] == scenario and c["method"] == method
                           and c["budget_episodes"] == budget and c.get("select_episodes", 0) == select),
                          key=lambda c: c["seed"])
            finals = [_final(c) for c in mine]
            chosen = ", ".join(str(_final(c)["round"]) for c in mine)
            name = "BC" if method == "bc" else "DAgger" if not select else \
                f"DAgger, the best round on {select} validation episodes (rounds {chosen})"
            episodes = [e for f in finals for e in f["eval"]]
            wins = sum(e["success"] for e in episodes)
            lo, hi = wilson_interval(wins, len(episodes))
            per_seed = ", ".join(f"{100 * f['eval_success']:.0f}" for f in finals)
            labels = statistics.fmean(_sum(c["rows"], "labels") for c in mine)
            replan = [_sum(c["rows"], "replan_labels") for c in mine]
            replan_s = [_sum(c["rows"], "replan_label_s") for c in mine]
            label_s = [_sum(c["rows"], "label_s") for c in mine]
            lines.append(
                f"| {scenario} | {name} | {mine[0]['budget_episodes']} "
                f"({labels:.0f}) | {100 * wins / len(episodes):.0f} ({100 * lo:.0f}-{100 * hi:.0f}) of "
                f"{len(episodes)} | {per_seed} | "
                f"{statistics.fmean(e['robustness_m'] for e in episodes):+.3f} | "
                f"{statistics.fmean(replan):.1f} ({labels:.0f}) | "
                f"{statistics.fmean(_sum(c['rows'], 'replan_cap_episodes') for c in mine):.1f} | "
                f"{statistics.fmean(replan_s):.2f} / "
                f"{statistics.fmean(label_s):.1f} | {statistics.fmean(f['wall_s'] for f in finals):.0f} |")
            if method != "dagger" or select:
                continue
            for k in range(len(mine[0]["rows"])):
                rows = [c["rows"][k] for c in mine if len(c["rows"]) > k]
                gap = [r["learner_label_mse"] for r in rows if r["learner_label_mse"] is not None]
                rounds_lines.append(
                    f"| {scenario} | {budget} | {k} | {rows[0]['beta']:.3g} | {rows[0]['dataset_labels']} | "
                    f"{statistics.fmean(r['replan_labels'] for r in rows):.1f} of {rows[0]['labels']} | "
                    f"{statistics.fmean(r['replan_label_s'] for r in rows):.2f} | "
                    f"{f'{statistics.fmean(gap):.3f}' if gap else '-'} | "
                    f"{statistics.fmean(r['val_mse'] for r in rows):.4f} | "
                    f"{100 * statistics.fmean(r['eval_success'] for r in rows):.0f} |")
    seeds = sorted({c["seed"] for c in cells})
    head = (f"Seeds {', '.join(map(str, seeds))}; 5 % thrust noise, 5 cm start noise; each policy evaluated alone on "
            f"{cells[0]['eval_episodes'] if cells else 0} episodes per seed (the same env seeds for every cell). "
            "Per method, the counts and seconds are means over seeds of the sums over rounds; an episode out of "
            "re-plans used the expert's MissionConfig.max_replans (3). Errors are mean squared action "
            "differences with the expert's labels.\n\n")
    return head + "\n".join(lines) + "\n\nDAgger per round (means over seeds):\n\n" + "\n".join(rounds_lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    from impact_env.errors import ImpactEnvError
    from impact_env.results_store import write_atomic

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenarios", default="throw_and_catch_exp,corridor")
    parser.add_argument("--seeds", default="0,1,2")
    parser.add_argument("--budgets", default="6,12", help="expert-labelled episodes per method and seed, each a row")
    parser.add_argument("--initial-share", type=float, default=1 / 3,
                        help="the share of a budget that DAgger's round 0 spends on the expert's own episodes")
    parser.add_argument("--rounds", type=int, default=4, help="DAgger's rounds after round 0")
    parser.add_argument("--beta-decay", type=float, default=0.5)
    parser.add_argument("--eval-episodes", type=int, default=20, help="episodes each policy flies alone")
    parser.add_argument("--epochs", type=int, default=30)
    parser.add_argument("--select-episodes", type=int, default=0,
                        help="DAgger returns its best round on this many validation episodes (0: its last round)")
    parser.add_argument("--table-only", action="store_true")
    args = parser.parse_args(argv)
    budgets = [int(b) for b in args.budgets.split(",")]
    for budget in budgets:
        initial = max(1, round(args.initial_share * budget))
        if args.rounds < 1 or initial >= budget or (budget - initial) % args.rounds:
            raise ImpactEnvError(f"budget {budget} minus DAgger's {initial} initial episodes must be a positive "
                                 f"multiple of --rounds {args.rounds} (both methods label the same episodes)")
    if args.select_episodes < 0:
        raise ImpactEnvError(f"--select-episodes must be >= 0, got {args.select_episodes}")
    store = _store()
    if not args.table_only:
        for scenario in args.scenarios.split(","):
            for budget in budgets:
                for seed in (int(s) for s in args.seeds.split(",")):
                    for method in METHODS:
                        if (scenario, budget, method, seed, args.select_episodes if method == "dagger" else 0) \
                                in store:
                            continue
                        cell = run_cell(scenario, budget, method, seed, args)
                        store.put(cell)
                        final = _final(cell)
                        print(f"{scenario} budget {budget} {method} seed {seed}: learner alone "
                              f"{100 * final['eval_success']:.0f} %, {cell['cell_wall_s']:.0f} s", flush=True)
    text = table()
    write_atomic(OUT / "table.md", text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

