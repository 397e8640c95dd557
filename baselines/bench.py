"""Expert-versus-learned benchmark: the same seeded episodes for every controller on every scenario.

    impact-env bench corridor,throw_and_catch_exp --controllers expert,ppo:runs/ppo_{scenario}_s0/model.zip,zero \
        --thrust-noise 0.05 --initial-position-noise-m 0.05

Controllers: ``expert``, ``random``, ``zero``, or a saved stable-baselines3 model as ``label:path.zip``
(or just ``path.zip``); ``{scenario}`` in a path is replaced by each scenario's name, since a policy is
trained per scenario. An RLlib policy is ``rllib:CHECKPOINT`` or ``label:rllib:CHECKPOINT`` (a run folder
of ``impact-env train ppo SCENARIO --engine rllib``, or one of its checkpoints). The expert's plan is computed
once per scenario and shared. Plans and episodes run on the sweep engine (:mod:`impact_env.sweep`): local
worker processes, or Ray tasks with ``--engine ray`` (on a cluster the model folders and plans travel to the
workers through Ray's object store). The results are the same on either engine, bit for bit, except the
controller's time per step, a wall-clock measurement. The nominal environment is deterministic, so every seed
would replay the same episode: pass noise options (thrust noise, initial position noise, restitution) to make
the seeds differ.

Writes into ``--out``, each file atomically (:mod:`impact_env.results_store`): ``episodes.csv`` (one row
per episode), ``summary.csv`` and ``summary.md`` (per scenario and controller: success rate, mean and std of
the final STL robustness, fuel, impacts, controller time per step), ``bench.png`` (bars per scenario, and the
first seed's trajectories side by side) and the expert's ``plans/``. The published run is
``results/baselines/`` (``baselines/reproduce.sh bench``).
"""

from __future__ import annotations

import csv
import functools
import json
import statistics
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from impact_env.errors import ImpactEnvError
from impact_env.results_store import atomic_path, write_atomic
from impact_env.sweep import EngineConfig, local_path, open_engine
from impact_env.transport.scenario import load_scenario

_CACHE: dict[tuple[str, str, Any], Any] = {}  # (scenario, controller, its files' digest): the controller


@dataclass(frozen=True)
class ControllerSpec:
    label: str
    name: str  # what make_controller takes: expert, random, zero, path/to/model.zip, rllib:CHECKPOINT
    options: tuple[tuple[str, str], ...] = ()
    trust_pickle: bool = False  # a model folder's pickles may be unpickled (--trust-pickle)

    @property
    def kind(self) -> str:
        """``sb3`` (a model.zip), ``rllib`` (an RLlib checkpoint) or the controller's name."""
        return "sb3" if self.name.endswith(".zip") else "rllib" if self.name.startswith("rllib:") else self.name


def model_path(spec: ControllerSpec, scenario: str) -> str:
    """The model file (or RLlib checkpoint) of ``spec`` for ``scenario`` (``{scenario}`` becomes its name)."""
    name = spec.name.removeprefix("rllib:") if spec.kind == "rllib" else spec.name
    return name.replace("{scenario}", scenario)


# the files of an SB3 run folder that a controller reads (not its checkpoints, logs and evaluations)
_SB3_FILES = ("model.zip", "vecnormalize.json", "vecnormalize.pkl", "train.json")


def parse_controllers(text: str, scenarios: list[str] | None = None,
                      trust_pickle: bool = False) -> list[ControllerSpec]:
    """``expert,random,zero,label:path.zip,label:rllib:CHECKPOINT`` -> specs; model files must exist for every
    scenario, and are checked (train.json, the zip's JSON, pickles: :func:`baselines.model_files.preflight`; an
    RLlib checkpoint's exported policy, :func:`baselines.rllib_policy.resolve_policy_dir`) before any worker
    starts."""
    from baselines.model_files import preflight

    specs = []
    for item in filter(None, (s.strip() for s in text.split(","))):
        if item.startswith("rllib:") or ":rllib:" in item:
            from baselines.rllib_policy import resolve_policy_dir

            # "label:rllib:PATH" (the label may itself be "rllib") or the bare "rllib:PATH"
            label, _, target = item.partition(":") if ":rllib:" in item else ("rllib", "", item)
            spec = ControllerSpec(label, target)
            for name in (scenarios or [""]) if "{scenario}" in target else [""]:
                resolve_policy_dir(model_path(spec, name))
            specs.append(spec)
            continue
        label, _, path = item.partition(":") if ":" in item else ("", "", item)
        target = path or item
        if target.endswith(".zip"):
            spec = ControllerSpec(label or Path(target).parent.name, target, trust_pickle=trust_pickle)
            for name in (scenarios or [""]) if "{scenario}" in target else [""]:
                try:
                    preflight(Path(model_path(spec, name)), trust_pickle)
                except ImpactEnvError as exc:
                    raise type(exc)(f"controller {item!r}: {exc}") from None
            specs.append(spec)
        else:
            from impact_env.catalogue import suggestion
            from impact_env.controllers import available_controllers
            from impact_env.errors import ControllerError

            # only names the episodes can build: the rest need a path (sb3's .zip, rllib:RUN)
            names = [n for n in available_controllers() if n not in ("sb3", "rllib")]
            if target not in names:
                raise ControllerError(f"controller {item!r}: unknown controller {target!r}"
                                      f"{suggestion(target, names)}; available: {', '.join(names)}, "
                                      "label:path/to/model.zip or label:rllib:RUN")
            specs.append(ControllerSpec(label or target, target))
    if not specs:
        raise ImpactEnvError("--controllers is empty")
    return specs


def _controller(scenario_name: str, scenario: Any, spec: ControllerSpec, files: Any):
    """The worker's controller for (scenario, spec), built once per worker process (the expert compiles its
    MPCs once); ``files`` is the shared plan file or model folder (see :meth:`impact_env.sweep.Engine.share`)."""
    from impact_env.controllers import make_controller

    key = (scenario_name, spec.name, getattr(files, "digest", files))
    if key not in _CACHE:
        path = None if files is None else local_path(files)
        if spec.kind == "sb3":
            if path is None:
                raise ImpactEnvError(f"controller {spec.label!r} needs its model folder")
            _CACHE[key] = make_controller(str(Path(path) / "model.zip"), scenario,
                                          trust_pickle=True if spec.trust_pickle else None)
        elif spec.kind == "rllib":
            _CACHE[key] = make_controller(f"rllib:{path}", scenario)
        else:
            _CACHE[key] = make_controller(spec.name, scenario, plan=path if spec.name == "expert" else None)
    return _CACHE[key]


def _impact_options(env_options: dict[str, Any]) -> dict[str, Any]:
    """The impact env's keywords: the tether stations' own options left out (their defaults, checked before)."""
    from impact_env.cli_options import STATION_DEFAULTS

    return {k: v for k, v in env_options.items() if k not in STATION_DEFAULTS}


def _episode(job: tuple[str, ControllerSpec, int, Any, dict[str, Any], bool]) -> dict[str, Any]:
    from baselines import tether
    from impact_env.rollout import robot_object_impacts, run_episode
    from impact_env.transport.gym_env import TransportEnv

    scenario_name, spec, seed, files, env_options, first = job
    if tether.is_station(scenario_name):
        from impact_env.tether.station import load_station

        station = load_station(scenario_name)
        controller = _controller(scenario_name, station, spec, files)
        res = run_episode(tether.make_env(station, **tether.env_options(env_options, scenario_name)), controller,
                          seed=seed)
        hits = 0
    else:
        scenario = load_scenario(scenario_name)
        controller = _controller(scenario_name, scenario, spec, files)
        res = run_episode(TransportEnv(scenario, **_impact_options(env_options)), controller, seed=seed)
        hits = len(robot_object_impacts(scenario, res.impacts))
    return {"scenario": scenario_name, "controller": spec.label, "seed": seed, "success": res.success,
            "robustness": res.robustness, "fuel_Ns": res.fuel_Ns, "impacts": hits,
            "controller_ms": float(np.mean(res.controller_ms)), "positions": res.positions if first else None}


def plan_expert(name: str) -> dict[str, Any]:
    """The expert's plan of one scenario (the spatially robust MILP) or station (the exact tether planner), as
    JSON data: a sweep job, so that several scenarios are planned side by side."""
    from baselines import tether

    if tether.is_station(name):
        from impact_env.tether.station import load_station
        from planners.tether.reachability import plan_reachability

        return plan_reachability(load_station(name)).to_dict()
    from planners.offline.spatially_robust import plan_spatially_robust

    return plan_spatially_robust(load_scenario(name)).to_dict()


def run_bench(scenarios: list[str], controllers: list[ControllerSpec], episodes: int, out: Path,
              workers: int | None = None, env_options: dict[str, Any] | None = None,
              engine: EngineConfig | None = None, seed: int = 0, quiet: bool = False) -> list[dict[str, Any]]:
    """Run every (scenario, controller, seed) and write the outputs; returns the summary rows.

    ``env_options`` (TransportEnv keywords such as ``thrust_noise``, and TetherEnv's for stations) apply to
    every episode; they are checked once here, so a bad value is one clear error rather than one per worker.
    The episodes of every scenario and controller are seeded ``seed``, ``seed + 1``, ... ``seed + episodes -
    1``. ``engine`` says where the plans and episodes run (default: ``workers`` local processes). ``out`` is
    checked (and created) after the options and before any plan or episode; ``quiet`` drops the line per
    episode.
    """
    from baselines import tether
    from impact_env.results_store import check_output_folder
    from impact_env.transport.core import TransportCore

    env_options = dict(env_options or {})
    for name in scenarios:
        if tether.is_station(name):
            tether.make_env(name, **tether.env_options(env_options, name)).close()
        else:
            TransportCore(name, **_impact_options(env_options))
    check_output_folder(out, "--out")
    engine = engine or EngineConfig("local", workers)
    n_jobs = len(scenarios) * len(controllers) * episodes
    with open_engine(engine, n_jobs=n_jobs) as pool:
        planned = [s for s in scenarios if any(c.name == "expert" for c in controllers)]
        plan_files: dict[str, Path] = {}
        for name, plan in zip(planned, pool.map(plan_expert, planned)):
            plan_files[name] = write_atomic(out / "plans" / f"{name}.json", json.dumps(plan, indent=1))
        shared: dict[tuple[str, str], Any] = {}
        for s in scenarios:
            for c in controllers:
                if c.name == "expert":
                    shared[s, c.name] = pool.share(plan_files[s])
                elif c.kind == "sb3":
                    folder = Path(model_path(c, s)).parent
                    shared[s, c.name] = pool.share(folder, include=_SB3_FILES)
                elif c.kind == "rllib":
                    from baselines.rllib_policy import resolve_policy_dir

                    shared[s, c.name] = pool.share(resolve_policy_dir(model_path(c, s)))
        jobs = [(s, c, k, shared.get((s, c.name)), env_options, k == seed)
                for s in scenarios for c in controllers for k in range(seed, seed + episodes)]
        results = []
        for k, r in enumerate(pool.map(_episode, jobs), 1):
            results.append(r)
            if not quiet:
                print(f"  [{k}/{len(jobs)}] {r['scenario']} {r['controller']} seed {r['seed']}: "
                      f"rho {r['robustness']:+.3f} {'ok' if r['success'] else 'fail'}", flush=True)
        if not quiet:
            print(f"  {pool.describe()}: {pool.placement_summary()}", flush=True)
    # every output is written atomically (impact_env.results_store): a kill leaves the old file or the new one
    with atomic_path(out / "episodes.csv") as tmp, open(tmp, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=[k for k in results[0] if k != "positions"])
        writer.writeheader()
        writer.writerows({k: v for k, v in r.items() if k != "positions"} for r in results)
    summary = _summarise(results, scenarios, controllers)
    with atomic_path(out / "summary.csv") as tmp, open(tmp, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(summary[0]))
        writer.writeheader()
        writer.writerows(summary)
    options = ", ".join(f"{k}={v}" for k, v in env_options.items()) or "nominal (no noise)"
    write_atomic(out / "summary.md", f"{episodes} seeded episodes per controller; environment options: {options}\n\n"
                 + markdown_table(summary) + "\n")
    with atomic_path(out / "bench.png") as tmp:
        _figure(results, summary, scenarios, controllers, tmp)
    return summary


def _summarise(results, scenarios, controllers) -> list[dict[str, Any]]:
    rows = []
    for s in scenarios:
        for c in controllers:
            rs = [r for r in results if r["scenario"] == s and r["controller"] == c.label]
            rho = [r["robustness"] for r in rs]
            rows.append({"scenario": s, "controller": c.label, "episodes": len(rs),
                         "success_rate": float(np.mean([r["success"] for r in rs])),
                         "robustness_mean": float(np.mean(rho)), "robustness_std": float(np.std(rho)),
                         "fuel_Ns": float(np.mean([r["fuel_Ns"] for r in rs])),
                         "impacts": float(np.mean([r["impacts"] for r in rs])),
                         "ms_per_step": statistics.median(r["controller_ms"] for r in rs)})
    return rows


def markdown_table(summary: list[dict[str, Any]]) -> str:
    lines = ["| scenario | controller | episodes | success | robustness mean +- std (m) | fuel N s | impacts | "
             "ms / step |", "|---|---|---:|---:|---:|---:|---:|---:|"]
    for r in summary:
        lines.append(f"| {r['scenario']} | {r['controller']} | {r['episodes']} | {100 * r['success_rate']:.0f}% | "
                     f"{r['robustness_mean']:+.3f} +- {r['robustness_std']:.3f} | {r['fuel_Ns']:.1f} | "
                     f"{r['impacts']:.1f} | {r['ms_per_step']:.2f} |")
    return "\n".join(lines)


def _figure(results, summary, scenarios, controllers, path: Path) -> None:
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    from baselines import tether
    from impact_env.transport.plotting import OBJECT_TRACE_COLOURS, draw_scenario, trace_colours

    n_c = len(controllers)
    fig = Figure(figsize=(3.2 * (n_c + 1) + 1.6, 3.6 * len(scenarios)), layout="constrained")
    axes = fig.subplots(len(scenarios), n_c + 1, squeeze=False)
    labels = [c.label for c in controllers]
    for i, s in enumerate(scenarios):
        rows = {r["controller"]: r for r in summary if r["scenario"] == s}
        ax = axes[i][0]
        ax.bar(labels, [rows[c]["robustness_mean"] for c in labels],
               yerr=[rows[c]["robustness_std"] for c in labels], color="0.55", alpha=0.9, capsize=3)
        ax.axhline(0.0, color="k", lw=0.8)
        for k, c in enumerate(labels):
            ax.text(k, 0, f"{100 * rows[c]['success_rate']:.0f}%", ha="center", va="bottom", fontsize=8)
        ax.set_title(f"{s}: robustness (m), success %", fontsize=9)
        ax.tick_params(axis="x", labelrotation=30, labelsize=8)
        ax.legend(handles=[Patch(fc="0.55", label="mean robustness +- std"),
                           Line2D([], [], ls="", marker="$\\%$", color="k", label="success rate")], fontsize=7,
                  loc="lower left")
        if tether.is_station(s):
            from impact_env.tether.plotting import draw_station
            from impact_env.tether.station import load_station

            draw = functools.partial(draw_station, load_station(s))
            names, colours = ["cargo"], [OBJECT_TRACE_COLOURS[0]]  # a station's trace is the cargo's path
        else:
            scenario = load_scenario(s)
            draw = functools.partial(draw_scenario, scenario)
            names = [body.name for body in scenario.bodies]
            colours = trace_colours(scenario)  # the colours of every other figure: robots blues, objects oranges
        for k, c in enumerate(labels):
            ax = axes[i][k + 1]
            draw(ax)
            ax.get_legend() and ax.get_legend().remove()
            traj = next(r["positions"] for r in results if r["scenario"] == s and r["controller"] == c
                        and r["positions"] is not None)
            for b, name in enumerate(names[:traj.shape[1]]):
                ax.plot(traj[:, b, 0], traj[:, b, 1], lw=1.2, color=colours[b], zorder=5, label=name)
            ax.set_title(f"{c} (seed {next(r['seed'] for r in results if r['positions'] is not None)})",
                         fontsize=9)
        axes[i][-1].legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8, title="paths")
    fig.savefig(path, dpi=100)
