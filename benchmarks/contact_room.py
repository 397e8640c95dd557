"""Generated tasks whose plans lack contact room, re-planned with the room rows and flown against the old plans.

The task filter plans generated tasks with the spatially robust planner, whose robots were points: a push that sends
an object away from a wall could ask the disc robot to stand beyond that wall. The filter keeps the room when asked
(``FilterConfig.contact_cones``, the impact-robust planner's rows in the spatially robust model). This takes a folder
of kept tasks planned without the rows (``--tasks``), measures every plan's contacts
(:func:`planners.plan.contact_room.contacts_without_room`), re-plans those that lack room with the filter's config and
``--cones`` cones (default 8), and flies the old and the new plan of each with the expert (``--stack``, default
``all``) under each condition (nominal and 0.02 m/s post-impact noise) on ``--seeds`` env seeds, in this tree, so the
two plans are paired on the same episodes. Verdicts and flights are lines of ``--out`` (``verdicts.jsonl``,
``flights.jsonl``; a stopped run resumes); the table: the re-plans' verdicts, robustness and planning time, then per
condition the old plans' and the new plans' success (Wilson 95 %), the episodes only one delivers and McNemar's exact
p. From the repository root:

    python -m benchmarks.contact_room --tasks results/task_generator/throw_and_catch --out results/contact_room
    python -m benchmarks.contact_room --out results/contact_room --table-only
"""

from __future__ import annotations

import argparse
import statistics
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

CONDITIONS = {"nominal": {}, "impact 0.02": {"impact_velocity_noise_mps": 0.02}}


def _plan_path(out: Path, name: str) -> Path:
    return out / f"{name}.plan.json"


def replan(job: tuple[str, str, str, int]) -> dict:
    """Re-plan one task (name, TOML text, out folder, cones) with the filter's config and the room rows; its
    verdict as a dict, the plan saved next to the verdicts."""
    from dataclasses import asdict

    from impact_env.results_store import atomic_path
    from impact_env.transport.scenario_toml import scenario_from_toml
    from planners.task_filter import FilterConfig, filter_scenario

    name, text, out, cones = job
    verdict, plan = filter_scenario(scenario_from_toml(text, source=name), FilterConfig(contact_cones=cones))
    if plan is not None:
        with atomic_path(_plan_path(Path(out), name)) as tmp:
            plan.save(tmp)
    return asdict(verdict)


def fly_job(job: dict) -> dict:
    """Fly one (task, plan kind, condition, seed) with the expert; its record."""
    from benchmarks.task_generator import fly
    from impact_env.transport.scenario_toml import scenario_from_toml
    from planners.expert.stacks import stack_config
    from planners.plan import Plan

    scenario = scenario_from_toml(job["toml"], source=job["name"])
    plan = Plan.load(job["plan_path"])
    flight = fly(scenario, plan, job["seed"], config=stack_config(job["stack"]),
                 env_options=CONDITIONS[job["condition"]])
    return {"name": job["name"], "plan": job["plan"], "condition": job["condition"], "seed": job["seed"],
            "stack": job["stack"], "success": flight["success"], "robustness": flight["robustness_m"],
            "impacts": flight["impacts"], "planned_impacts": len(plan.impacts), "wall_s": flight["wall_s"]}


def table(verdicts: list[dict], flights: list[dict], flagged: int, kept: int) -> str:
    import numpy as np

    from benchmarks.residual import mcnemar
    from benchmarks.task_generator import wilson

    lines = [f"{flagged} of {kept} kept plans have a contact without room; re-planned with the room rows:", ""]
    reasons: dict[str, int] = {}
    for v in verdicts:
        reasons[v["reason"]] = reasons.get(v["reason"], 0) + 1
    lines.append("| re-plans | kept | verdicts | rho old -> new (mean, kept) | planning s (median) |")
    lines.append("|---:|---:|---|---|---:|")
    both = [v for v in verdicts if v["kept"]]
    old_rho = [v["old_robustness_m"] for v in both]
    new_rho = [v["robustness_m"] for v in both]
    rho = f"{statistics.fmean(old_rho):.3f} -> {statistics.fmean(new_rho):.3f}" if both else "-"
    plan_s = f"{statistics.median(v['plan_s'] for v in verdicts):.1f}" if verdicts else "-"
    lines.append(f"| {len(verdicts)} | {len(both)} | {', '.join(f'{k} {n}' for k, n in sorted(reasons.items()))} | "
                 f"{rho} | {plan_s} |")
    lines += ["", "Tasks re-planned and kept, old and new plan on the same episodes; then the tasks the filter now "
              "refuses, flown with their old plans (what refusing them loses):", "",
              "| condition | stack | tasks | plan | episodes (tasks) | success % (95 % CI) | robustness m (mean) | "
              "only new / only old | McNemar p |", "|---|---|---|---|---:|---:|---:|---|---:|"]
    groups: dict[tuple, dict[str, dict]] = {}
    for f in flights:
        groups.setdefault((f["condition"], f["stack"]), {}).setdefault(f["plan"], {})[(f["name"], f["seed"])] = f
    refused = {v["name"] for v in verdicts if not v["kept"]}
    for (condition, stack), plans in sorted(groups.items()):
        rows = [f for key, f in plans.get("old", {}).items() if key[0] in refused]
        if rows:
            k, n = sum(r["success"] for r in rows), len(rows)
            lo, hi = wilson(k, n)
            refused_rows = (f"| {condition} | {stack} | refused | old | {n} ({len({r['name'] for r in rows})}) | "
                            f"{100 * k / n:.0f} ({100 * lo:.0f}-{100 * hi:.0f}) | "
                            f"{statistics.fmean(r['robustness'] for r in rows):+.3f} | - | - |")
        else:
            refused_rows = ""
        paired = sorted(set(plans.get("old", {})) & set(plans.get("new", {})))
        for kind in ("old", "new"):
            rows = [plans[kind][key] for key in paired]
            if not rows:
                continue
            k, n = sum(r["success"] for r in rows), len(rows)
            lo, hi = wilson(k, n)
            versus, p = "-", "-"
            if kind == "new":
                test = mcnemar(np.array([plans["old"][key]["success"] for key in paired]),
                               np.array([plans["new"][key]["success"] for key in paired]))
                versus, p = f"{test['only_residual']} / {test['only_expert']}", f"{test['p_two_sided']:.3f}"
            lines.append(f"| {condition} | {stack} | kept | {kind} | {n} ({len({r['name'] for r in rows})}) | "
                         f"{100 * k / n:.0f} ({100 * lo:.0f}-{100 * hi:.0f}) | "
                         f"{statistics.fmean(r['robustness'] for r in rows):+.3f} | {versus} | {p} |")
        if refused_rows:
            lines.append(refused_rows)
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    from impact_env.results_store import CellStore, write_atomic
    from planners.plan.contact_room import contacts_without_room
    from planners.task_filter import load_kept

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tasks", type=Path, default=Path("results/task_generator/throw_and_catch"),
                    help="a folder of kept tasks planned without the room rows (default: throw_and_catch's)")
    ap.add_argument("--out", type=Path, default=Path("results/contact_room"), help="results folder")
    ap.add_argument("--seeds", type=int, default=1, help="env seeds per task and condition (default 1)")
    ap.add_argument("--stack", default="all", help="the expert's stack (default all)")
    ap.add_argument("--workers", type=int, default=1, help="processes (default 1)")
    ap.add_argument("--cones", type=int, default=8, help="the room rows' cone count (FilterConfig.contact_cones, "
                    "default 8)")
    ap.add_argument("--table-only", action="store_true", help="print the table of the stored cells and stop")
    args = ap.parse_args(argv)
    if args.seeds < 1 or args.workers < 1 or args.cones < 4:
        ap.error("--seeds and --workers must be >= 1, --cones >= 4")
    args.out.mkdir(parents=True, exist_ok=True)
    verdicts = CellStore(args.out / "verdicts.jsonl", key=lambda c: c["name"])
    flights = CellStore(args.out / "flights.jsonl",
                        key=lambda c: (c["name"], c["plan"], c["condition"], c["seed"], c["stack"]))
    kept = load_kept(args.tasks)
    flagged = [(sc, plan, cell) for sc, plan, cell in kept if contacts_without_room(plan, sc)]
    if not args.table_only:
        print(f"{len(flagged)} of {len(kept)} kept plans in {args.tasks} have a contact without room", flush=True)
        todo = [(cell["name"], (args.tasks / f"{cell['name']}.toml").read_text(encoding="utf-8"), str(args.out),
                 args.cones) for _, _, cell in flagged if cell["name"] not in verdicts]
        old = {cell["name"]: cell for _, _, cell in flagged}
        with ProcessPoolExecutor(args.workers) as pool:
            for verdict in pool.map(replan, todo):
                verdict["old_robustness_m"] = old[verdict["name"]]["robustness_m"]
                verdicts.put(verdict)
                print(f"  {verdict['name']}: {verdict['reason']} rho {verdict['robustness_m']} "
                      f"(was {verdict['old_robustness_m']:.3f}), {verdict['plan_s']:.1f} s", flush=True)
        jobs = []
        for _, _, cell in flagged:
            name = cell["name"]
            v = verdicts.get(name)
            if v is None:
                continue
            text = (args.tasks / f"{name}.toml").read_text(encoding="utf-8")
            plans = [("old", args.tasks / f"{name}.plan.json")] + ([("new", _plan_path(args.out, name))]
                                                                   if v["kept"] else [])
            for kind, path in plans:  # a refused task's old plan too: what refusing it loses
                for condition in CONDITIONS:
                    for seed in range(args.seeds):
                        job = {"name": name, "toml": text, "plan": kind, "plan_path": str(path),
                               "condition": condition, "seed": seed, "stack": args.stack}
                        if (name, kind, condition, seed, args.stack) not in flights:
                            jobs.append(job)
        with ProcessPoolExecutor(args.workers) as pool:
            for record in pool.map(fly_job, jobs):
                flights.put(record)
                print(f"  {record['name']} {record['plan']} {record['condition']} seed {record['seed']}: "
                      f"{'delivered' if record['success'] else 'failed'} {record['robustness']:+.3f} m", flush=True)
    text = table(list(verdicts.cells()), list(flights.cells()), len(flagged), len(kept))
    write_atomic(args.out / "table.md", text + "\n")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
