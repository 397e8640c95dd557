"""BC, then BC+RL from it, per scenario and seed: ``python -m benchmarks.bc_rl``.

For each scenario and seed, under 5 % thrust noise and 5 cm start noise:

- BC: the expert flies ``--demo-episodes`` seeded episodes with the committed spatially robust plan of
  ``results/robustness/plans/`` and a policy is fitted to every step of them (``impact-env dagger --rounds 0``,
  the fit of ``impact-env bc``, as :mod:`benchmarks.dagger` does);
- BC+RL: that policy fine-tuned by PPO on the batched world for ``--frames`` env-steps with the decaying BC
  term on the same expert pairs (:mod:`baselines.batched.bc_rl`, its default settings unless given).

Both policies fly the same ``--eval-episodes`` seeded episodes on the pymunk env (seeds 1,000,000 on, the
episodes of ``results/expert_vs_learned``, whose expert cell on them is the reference row), deterministically.
Reported per scenario and method: the success rate and mean robustness, as the interquartile mean over seeds
with rliable's 95 % bootstrap interval over seeds when there are 3 or more, each seed's rate, the share of the
expert's mean robustness, the expert-labelled env-steps and RL env-steps, and the wall clock per seed (BC:
labelling and fit; BC+RL: its fine-tuning, without the evaluations). Cells (scenario, demo episodes, frames,
seed) go to ``results/bc_rl/cells.jsonl`` as they finish, runs to ``runs/bc_rl_bench/``; a rerun resumes the
run in flight and skips finished cells; ``table.md`` is rewritten at the end.

    nice -n 5 python -m benchmarks.bc_rl [--scenarios corridor,obstacle_avoidance] [--seeds 0,1,2] [--frames 262144]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path
from typing import Any

OUT = Path("results/bc_rl")
RUNS = Path("runs/bc_rl_bench")
PLANS = Path("results/robustness/plans")
EXPERT = Path("results/expert_vs_learned/cells.jsonl")
NOISE = {"thrust_noise": 0.05, "initial_position_noise_m": 0.05}
MIN_SEEDS = 3  # rliable's interval over fewer seeds says little


def _store():
    from impact_env.results_store import CellStore

    return CellStore(OUT / "cells.jsonl",
                     key=lambda c: (c["scenario"], c["demo_episodes"], c["frames"], c["variant"], c["seed"]))


def _scores(evaluation: dict[str, Any]) -> dict[str, Any]:
    ref = evaluation["pymunk"]
    return {"success_rate": ref["success_rate"], "robustness_mean": ref["robustness_mean"],
            "robustness": ref["robustness"], "expert_action_mse": evaluation["expert_action_mse"]}


def run_cell(scenario: str, seed: int, args: argparse.Namespace) -> dict[str, Any]:
    import json

    from baselines.batched.bc_rl import BcRlConfig, run
    from baselines.dagger import DAggerConfig, dagger

    bc_dir = dagger(DAggerConfig(
        scenario, rounds=0, initial_episodes=args.demo_episodes, eval_episodes=0,
        plan=str(PLANS / f"{scenario}.json"), env_options=NOISE, epochs=args.epochs, seed=seed,
        out=str(RUNS / f"bc_{scenario}_e{args.demo_episodes}_s{seed}"), resume=True, quiet=True))
    bc_row = json.loads((bc_dir / "dagger.json").read_text())["rounds"][0]
    config = BcRlConfig(scenario, str(bc_dir), seed=seed, frames=args.frames, bc_weight=args.bc_weight,
                        bc_half_life_frames=args.bc_half_life or None,
                        critic_warmup_rollouts=args.critic_warmup_rollouts, log_std=args.log_std,
                        lr=args.lr, num_envs=args.num_envs, n_steps=args.n_steps, batch_size=args.batch_size,
                        normalize_advantage=args.normalize_advantage, eval_episodes=args.eval_episodes, **NOISE)
    result = run(config, RUNS / f"bc_rl_{scenario}_e{args.demo_episodes}_f{args.frames}_{args.variant}_s{seed}")
    return {"scenario": scenario, "seed": seed, "demo_episodes": args.demo_episodes, "frames": args.frames,
            "variant": args.variant,
            "env_options": NOISE, "eval_episodes": args.eval_episodes,
            "bc": {"labels": bc_row["labels"], "wall_s": round(bc_row["wall_s"], 1), "val_mse": bc_row["val_mse"],
                   **_scores(result["evaluation_init"])},
            "bc_rl": {"env_steps": result["env_steps"], "wall_s": result["wall_s"],
                      "env_steps_per_s": result["env_steps_per_s"], **_scores(result["evaluation"])},
            "config": result["config"], "load_average_1min_at_end": round(os.getloadavg()[0], 2)}


def _expert(scenario: str, episodes: int) -> dict[str, float] | None:
    """The expert's success and mean robustness on the first ``episodes`` of the same seeded episodes."""
    from impact_env.results_store import CellStore

    if not EXPERT.exists():
        return None
    cell = CellStore(EXPERT, key=lambda c: (c["controller"], c["scenario"])).get(("expert", scenario))
    if cell is None or cell["env_options"] != NOISE or len(cell["episodes"]) < episodes:
        return None
    eps = cell["episodes"][:episodes]
    return {"success_rate": statistics.fmean(bool(e["success"]) for e in eps),
            "robustness_mean": statistics.fmean(float(e["robustness"]) for e in eps)}


def _over_seeds(values: list[float], scale: float = 1.0, form: str = "+.3f") -> str:
    """The IQM over seeds [rliable's 95 % bootstrap interval] with 3+ seeds, else the mean (said so)."""
    if len(values) < MIN_SEEDS:
        return f"{scale * statistics.fmean(values):{form}} (mean)"
    from benchmarks.rl_at_scale_report import iqm_interval

    point, lo, hi = iqm_interval(values, reps=2000)
    return f"{scale * point:{form}} [{scale * lo:{form}}, {scale * hi:{form}}]"


def _settings(cfg: dict[str, Any]) -> str:
    """A BC+RL run's settings in a few words."""
    half = cfg["bc_half_life_frames"]
    return (f"BC weight {cfg['bc_weight']:g}, " + (f"half-life {half:,}" if half else "constant") +
            f", lr {cfg['lr']:g}" + ("" if cfg["log_std"] is None else f", log std {cfg['log_std']:g}") +
            (", advantages normalised" if cfg["normalize_advantage"] else ""))


def _row(scenario: str, label: str, cells: list[dict], method: str, rl_steps: str, settings: str,
         expert: dict[str, float] | None) -> str:
    rows = [c[method] for c in cells]
    success = [r["success_rate"] for r in rows]
    robustness = [r["robustness_mean"] for r in rows]
    share = "-"
    if expert and expert["robustness_mean"] > 0:  # a share of a negative mean says nothing more than its sign
        share = (f"{100 * statistics.fmean(robustness) / expert['robustness_mean']:.0f} %"
                 if statistics.fmean(robustness) > 0 else "below 0")
    return (f"| {scenario} | {label} | {settings} | {','.join(str(c['seed']) for c in cells)} | "
            f"{statistics.fmean(c['bc']['labels'] for c in cells):,.0f} | {rl_steps} | "
            f"{_over_seeds(success, 100, '.0f')} | {' / '.join(f'{100 * s:.0f}' for s in success)} | "
            f"{_over_seeds(robustness)} | {share} | "
            f"{statistics.fmean(r['expert_action_mse'] for r in rows):.2e} | "
            f"{statistics.fmean(r['wall_s'] for r in rows):.0f} |")


def table() -> str:
    cells = list(_store())
    if not cells:
        return "No cells yet.\n"
    lines = ["| scenario | method | settings | seeds | expert-labelled env-steps | RL env-steps | "
             "success % IQM [95 % CI] | per seed % | robustness m IQM [95 % CI] | of the expert's robustness | "
             "action error vs expert | wall clock s per seed |", "|" + "---|" * 12]
    for scenario, demos in dict.fromkeys((c["scenario"], c["demo_episodes"]) for c in cells):
        mine = [c for c in cells if (c["scenario"], c["demo_episodes"]) == (scenario, demos)]
        expert = _expert(scenario, mine[0]["eval_episodes"])
        if expert is not None:
            lines.append(f"| {scenario} | expert | - | - | - | - | {100 * expert['success_rate']:.0f} | - | "
                         f"{expert['robustness_mean']:+.3f} | 100 % | 0 | - |")
        runs = dict.fromkeys((c["frames"], c["variant"]) for c in mine)
        first = sorted((c for c in mine if (c["frames"], c["variant"]) == next(iter(runs))), key=lambda c: c["seed"])
        lines.append(_row(scenario, "BC", first, "bc", "-", f"{demos} expert episodes", expert))
        for frames, variant in runs:
            group = sorted((c for c in mine if (c["frames"], c["variant"]) == (frames, variant)),
                           key=lambda c: c["seed"])
            lines.append(_row(scenario, f"BC+RL ({variant})", group, "bc_rl",
                              f"{statistics.fmean(c['bc_rl']['env_steps'] for c in group):,.0f}",
                              _settings(group[0]["config"]), expert))
    c0 = cells[0]
    cfg = c0["config"]
    head = (f"Each policy flown deterministically on the same {c0['eval_episodes']} pymunk episodes per seed "
            "(seeds 1,000,000 on; 5 % thrust noise, 5 cm start noise); the expert row is the expert on those "
            "episodes (results/expert_vs_learned). IQM over seeds with rliable's 95 % bootstrap interval over "
            f"seeds ({MIN_SEEDS}+ seeds; else the mean). BC: the expert's episodes, every step labelled, "
            "fitted as `impact-env bc` does (its row: the BC policies the first BC+RL row started from). BC+RL: "
            f"PPO on the batched world from the BC policy, a critic warm-up of {cfg['critic_warmup_rollouts']} "
            f"rollout, {cfg['num_envs']} envs x the horizon's steps per rollout (one whole episode of each), the "
            "settings as the row says; its RL env-steps include the warm-up. The action error is the mean "
            "squared difference of the deterministic action from the expert's, on 2,048 of its pairs. Wall "
            "clock: BC, the expert's episodes and the fit; BC+RL, the fine-tuning alone (one torch thread, the "
            "shared 2-core machine). Made by `python -m benchmarks.bc_rl`.\n\n")
    return head + "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    from impact_env.results_store import write_atomic

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenarios", default="corridor,obstacle_avoidance")
    parser.add_argument("--seeds", default="0,1,2")
    parser.add_argument("--demo-episodes", type=int, default=12, help="expert episodes of the BC policy")
    parser.add_argument("--epochs", type=int, default=30, help="BC's passes over the expert episodes")
    parser.add_argument("--frames", type=int, default=2_000_000, help="RL env-steps of BC+RL (whole rollouts)")
    parser.add_argument("--bc-weight", type=float, default=1.0)
    parser.add_argument("--bc-half-life", type=int, default=1_000_000, help="env-steps; 0: a constant weight")
    parser.add_argument("--critic-warmup-rollouts", type=int, default=1)
    parser.add_argument("--log-std", type=float, default=None, help="the start's log std (default: BC's)")
    parser.add_argument("--lr", type=float, default=1e-4)
    parser.add_argument("--num-envs", type=int, default=256)
    parser.add_argument("--n-steps", type=int, default=None, help="default: the scenario's horizon")
    parser.add_argument("--batch-size", type=int, default=None)
    parser.add_argument("--normalize-advantage", action="store_true", help="SB3's default; off in BcRlConfig")
    parser.add_argument("--eval-episodes", type=int, default=100)
    parser.add_argument("--variant", default="default",
                        help="a name for these BC+RL settings: a cell is (scenario, demo episodes, frames, variant, "
                             "seed), and its run folder carries the name")
    parser.add_argument("--table-only", action="store_true")
    args = parser.parse_args(argv)
    store = _store()
    if not args.table_only:
        for scenario in args.scenarios.split(","):
            for seed in (int(s) for s in args.seeds.split(",")):
                if (scenario, args.demo_episodes, args.frames, args.variant, seed) in store:
                    continue
                start = time.perf_counter()
                cell = run_cell(scenario, seed, args)
                store.put(cell)
                print(f"{scenario} seed {seed}: BC {100 * cell['bc']['success_rate']:.0f} % -> BC+RL "
                      f"{100 * cell['bc_rl']['success_rate']:.0f} %, {time.perf_counter() - start:.0f} s", flush=True)
    text = table()
    write_atomic(OUT / "table.md", text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
