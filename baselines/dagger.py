"""DAgger (Ross, Gordon and Bagnell 2011) with the expert as the oracle: ``impact-env dagger SCENARIO``.

    run = dagger(DAggerConfig("corridor", plan="plan.json", rounds=3, episodes_per_round=4))

Round 0 is behaviour cloning: the expert flies ``initial_episodes`` seeded episodes (or round 0 is read from
the Minari dataset of ``impact-env record``, ``dataset_dir``) and a PPO ``MlpPolicy`` is fitted to them with
the loop of :mod:`baselines.bc` (:func:`~baselines.bc.fit_policy`). Each round i = 1..``rounds`` then flies
``episodes_per_round`` episodes of the mixed policy (the expert's action with probability
beta_i = ``beta_decay`` ** i per step, the learner's otherwise), the expert labels every state visited
(:mod:`baselines.dagger_label`: it tracks the learner's world and re-plans from it when it must, counted and
timed), the labelled episodes join the data set, and a fresh policy is fitted to all of it.

Validation: the held-out share of round 0's expert episodes, the same in every round, so the validation
error of the rounds can be compared; the learner's error on the states it visited itself (against the
expert's labels, before the refit) is reported too. After each fit the learner flies ``eval_episodes``
episodes alone (env seeds from :data:`EVAL_SEED0`, which no training episode uses).

The policy a run returns: the last round's, or with ``select_episodes`` > 0 the best round's on that many
validation episodes of its own (env seeds from :data:`SELECT_SEED0`, used by no training or evaluation episode),
as Ross et al. return the best of their policies on validation: a round's refit can fall back (the corridor at 24
episodes, seed 2: 95 % after round 3, 25 % after round 4).

The run folder holds that policy, saved as :mod:`baselines.bc` saves one (``model.zip``,
``vecnormalize.json``, ``train.json``), so ``impact-env run --controller`` and ``bench`` fly it; each round's
policy in ``rounds/policy_NNN/`` (the next round's learner is its round's); each round's labelled episodes in
``rounds/round_NNN.npz``; and ``dagger.json``, one row per round and the ``selected_round`` (written last: a
round is done once it is there). ``resume=True`` continues a stopped run from its last round.

The ``imitation`` library's DAgger is not used: its 1.0.1 pins gymnasium 0.29 and stable-baselines3 2.2.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from baselines.bc import check_fit_fields, fit_policy, load_demonstrations, save_policy, split_episodes
from baselines.dagger_label import LabelledEpisode, labelled_episode
from baselines.model_files import LEGACY_NORMALIZATION_FILE, NORMALIZATION_FILE
from baselines.run_folder import check_run_folder, run_folder_path
from baselines.run_meta import scenario_fingerprint
from impact_env.config_checks import check_flag, check_instance, check_integer, check_number, check_text, fail
from impact_env.errors import ImpactEnvError
from impact_env.results_store import atomic_path, check_output_folder, write_atomic
from impact_env.transport.scenario import Scenario, load_scenario

__all__ = ["EVAL_SEED0", "SELECT_SEED0", "DAggerConfig", "dagger", "episode_seed", "load_round", "selected_round"]

EVAL_SEED0 = 1_000_000_000
"""The env seed of the learner's first evaluation episode (episode k: ``EVAL_SEED0 + k``)."""
SELECT_SEED0 = 1_500_000_000
"""The env seed of the first validation episode a round is selected on (``DAggerConfig.select_episodes``)."""
MAX_PER_ROUND = 1000  # episodes per round and rounds per run: the env seeds of episode_seed stay apart


@dataclass(frozen=True)
class DAggerConfig:
    """What :func:`dagger` runs (see the module docstring)."""

    scenario: str
    """The scenario (a shipped name or a scenario file)."""
    rounds: int = 4
    """DAgger rounds after round 0 (0: behaviour cloning only)."""
    initial_episodes: int = 10
    """Expert episodes flown for round 0 (unused with ``dataset_dir``)."""
    dataset_dir: str | None = None
    """Round 0 from the Minari dataset ``impact-env record --out DIR`` wrote; None: the expert flies round 0."""
    episodes_per_round: int = 5
    """Mixed-policy episodes labelled per round."""
    beta_decay: float = 0.5
    """Round i executes the expert's action with probability ``beta_decay ** i`` (in [0, 1]; 0: the learner's
    only)."""
    eval_episodes: int = 10
    """Episodes the learner flies alone after each fit, for its success (0: none)."""
    select_episodes: int = 0
    """Validation episodes the learner flies alone after each fit; the run returns the round with the most
    successes on them (ties: the higher mean robustness, then the later round). 0: the last round's policy."""
    plan: str | None = None
    """The expert's offline plan (a ``Plan`` JSON file); None: planned with the MILP at the start."""
    max_replans: int = 3
    """Mission re-plans the expert may run per episode (``MissionConfig.max_replans``)."""
    env_options: dict[str, Any] | None = None
    """TransportEnv options of every episode (e.g. ``{"thrust_noise": 0.05}``); None: nominal."""
    epochs: int = 30
    """Passes over the data set in each fit."""
    batch_size: int = 256
    """Observation-label pairs per Adam step."""
    learning_rate: float = 1e-3
    """Adam's learning rate."""
    ent_weight: float = 1e-3
    """Weight of the entropy bonus, against the negative log-likelihood."""
    validation_share: float = 0.1
    """Share of round 0's episodes held out for the validation error (see :func:`baselines.bc.split_episodes`)."""
    net_arch: tuple[int, ...] = (128, 128)
    """Hidden layer sizes of the policy and value networks."""
    seed: int = 0
    """Seed of the fits, the per-step choices and the training episodes' env seeds (:func:`episode_seed`)."""
    out: str | None = None
    """The run folder; None: ``<runs_dir>/dagger_<scenario>_s<seed>``."""
    runs_dir: str = "runs"
    """The parent of the default run folder."""
    resume: bool = False
    """Continue the run in the run folder after its last finished round (its settings must match)."""
    quiet: bool = False
    """No progress lines."""

    def __post_init__(self) -> None:
        check_text(self, "scenario", ImpactEnvError)
        check_integer(self, "rounds", ImpactEnvError, low=0, high=MAX_PER_ROUND - 1)
        for name in ("initial_episodes", "episodes_per_round"):
            check_integer(self, name, ImpactEnvError, low=1, high=MAX_PER_ROUND)
        check_text(self, "dataset_dir", ImpactEnvError, none="the expert flies round 0")
        check_number(self, "beta_decay", ImpactEnvError, low=0, high=1)
        check_integer(self, "eval_episodes", ImpactEnvError, low=0)
        check_integer(self, "select_episodes", ImpactEnvError, low=0, high=100_000_000)
        check_text(self, "plan", ImpactEnvError, none="planned with the MILP")
        check_integer(self, "max_replans", ImpactEnvError, low=0)
        check_instance(self, "env_options", ImpactEnvError, dict, what="a dict of TransportEnv options",
                       none="nominal")
        check_fit_fields(self)
        if self.seed >= 1000:
            fail("DAggerConfig.seed", self.seed, "< 1000 (the training env seeds are seed * 10**6 + ...)",
                 ImpactEnvError)
        check_run_folder(self, "dagger_<scenario>_s<seed>")
        check_flag(self, "resume", ImpactEnvError)

    def beta(self, round_: int) -> float:
        """The probability that round ``round_`` executes the expert's action (1 in round 0)."""
        return 1.0 if round_ == 0 else float(self.beta_decay ** round_)

    def settings(self) -> dict[str, Any]:
        """The fields a resumed run must share with the run it continues (all but the length and the output;
        ``select_episodes`` only when set, so that runs from before it resume)."""
        skip = {"rounds", "resume", "quiet", "out", "runs_dir"} | ({"select_episodes"} if not self.select_episodes
                                                                   else set())
        out = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name not in skip}
        out["net_arch"] = list(self.net_arch)
        return out


def episode_seed(seed: int, round_: int, episode: int) -> int:
    """The env seed of training episode ``episode`` of round ``round_`` in a run of seed ``seed``."""
    return seed * 1_000_000 + round_ * MAX_PER_ROUND + episode


def round_file(run_dir: Path, round_: int) -> Path:
    return run_dir / "rounds" / f"round_{round_:03d}.npz"


def save_round(path: Path, episodes: list[LabelledEpisode]) -> None:
    arrays: dict[str, np.ndarray] = {"episodes": np.array(len(episodes))}
    for k, ep in enumerate(episodes):
        arrays.update(ep.arrays(f"{k}/"))
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        np.savez_compressed(f, **arrays)  # type: ignore[arg-type]  # numpy's stubs miss str keys of arrays


def load_round(run_dir: str | Path, round_: int) -> list[LabelledEpisode]:
    """The labelled episodes of round ``round_`` of the run in ``run_dir``."""
    with np.load(round_file(Path(run_dir), round_), allow_pickle=False) as data:
        return [LabelledEpisode.from_arrays(data, f"{k}/") for k in range(int(data["episodes"]))]


def _expert(config: DAggerConfig, scenario: Scenario):
    from planners.expert import Expert, ExpertConfig
    from planners.online.mission import MissionConfig
    from planners.plan import Plan

    plan = Plan.load(config.plan) if config.plan else None
    return Expert(scenario, plan=plan, config=ExpertConfig(mission=MissionConfig(max_replans=config.max_replans)))


def _dataset_round(config: DAggerConfig, scenario: Scenario) -> list[LabelledEpisode]:
    """Round 0 from a recorded Minari dataset: the expert's actions are the labels, and nothing was timed."""
    out = []
    for k, (obs, act) in enumerate(load_demonstrations(scenario.name, config.dataset_dir)):
        n = len(obs)
        out.append(LabelledEpisode(-1 - k, obs, act, np.ones(n, bool), np.full_like(act, np.nan), np.zeros(n, bool),
                                   np.full(n, np.nan), 0, 0, False, 0, False, float("nan")))
    return out


def _round_row(round_: int, beta: float, new: list[LabelledEpisode], data: list[LabelledEpisode]) -> dict[str, Any]:
    """What a round's data collection measured (see :func:`dagger`)."""
    label_s = np.concatenate([e.label_s for e in new])
    replan = np.concatenate([e.replan_labels for e in new])
    timed = not np.isnan(label_s).any()
    mixed = [e for e in new if not e.expert_acted.all()]
    gap = (float(np.mean(np.concatenate([((e.learner_actions - e.labels) ** 2).mean(axis=1) for e in mixed])))
           if mixed else None)  # the learner's error on the states of its own round, before the refit
    return {"round": round_, "beta": beta, "episodes": len(new), "labels": int(len(label_s)),
            "dataset_episodes": len(data), "dataset_labels": int(sum(e.steps for e in data)),
            "expert_acted_share": float(np.mean(np.concatenate([e.expert_acted for e in new]))),
            "replan_labels": int(replan.sum()), "replan_attempts": sum(e.replan_attempts for e in new),
            "replans_accepted": sum(e.replans_accepted for e in new),
            "replan_cap_episodes": sum(e.replan_cap_reached for e in new),
            "replan_label_s": float(label_s[replan].sum()) if timed else None,
            "label_s": float(label_s.sum()) if timed else None,
            "label_ms_median": float(1e3 * np.median(label_s[~replan])) if timed and (~replan).any() else None,
            "local_replans": sum(e.local_replans for e in new),
            "rollout_success": float(np.mean([e.success for e in new])) if timed else None,
            "learner_label_mse": gap}


def _evaluate(config: DAggerConfig, scenario: Scenario, run_dir: Path) -> dict[str, Any]:
    """The saved learner alone on ``eval_episodes`` episodes, and on ``select_episodes`` validation ones."""
    from baselines.policy import SB3Controller
    from impact_env.rollout import run_episode
    from impact_env.transport.gym_env import TransportEnv

    out: dict[str, Any] = {"eval_success": None, "eval_robustness_m": None, "eval_ms_per_step": None, "eval": []}
    if config.eval_episodes == 0 and config.select_episodes == 0:
        return out
    learner = SB3Controller(scenario, run_dir / "model.zip")
    env = TransportEnv(scenario, **(config.env_options or {}))
    if config.eval_episodes:
        results = [run_episode(env, learner, seed=EVAL_SEED0 + k) for k in range(config.eval_episodes)]
        out = {"eval_success": float(np.mean([r.success for r in results])),
               "eval_robustness_m": float(np.mean([r.robustness for r in results])),
               "eval_ms_per_step": float(np.median(np.concatenate([r.controller_ms for r in results]))),
               "eval": [{"seed": r.seed, "success": bool(r.success), "robustness_m": float(r.robustness)}
                        for r in results]}
    if config.select_episodes:
        chosen_on = [run_episode(env, learner, seed=SELECT_SEED0 + k) for k in range(config.select_episodes)]
        out.update({"select_successes": int(sum(r.success for r in chosen_on)),
                    "select_robustness_m": float(np.mean([r.robustness for r in chosen_on]))})
    env.close()
    return out


def selected_round(rows: list[dict[str, Any]]) -> int:
    """The round a run returns (see ``DAggerConfig.select_episodes``): the most validation successes, then the
    higher mean robustness on them, then the later round; the last round when no row was validated."""
    scored = [(r["select_successes"], r["select_robustness_m"], r["round"]) for r in rows if "select_successes" in r]
    return max(scored)[2] if scored else rows[-1]["round"]


def _policy_folder(run_dir: Path, round_: int) -> Path:
    return run_dir / "rounds" / f"policy_{round_:03d}"


def _start(config: DAggerConfig, run_dir: Path) -> list[dict[str, Any]]:
    """The rows of the rounds already done (none for a new run); refuses to overwrite or mix runs."""
    state = run_dir / "dagger.json"
    if not state.is_file():
        return []
    if not config.resume:
        raise ImpactEnvError(f"{run_dir} holds a DAgger run already: continue it with --resume (resume=True), "
                             "or choose another --out")
    saved = json.loads(state.read_text())
    mine = json.loads(json.dumps(config.settings()))
    differ = sorted(k for k in mine if saved["settings"].get(k) != mine[k])
    if differ:
        raise ImpactEnvError(f"{run_dir} was run with other settings ({', '.join(differ)}: "
                             + "; ".join(f"{k} {saved['settings'].get(k)!r}, now {mine[k]!r}" for k in differ)
                             + "): resume it with the same ones, or choose another --out")
    return list(saved["rounds"])


def dagger(config: DAggerConfig) -> Path:
    """Run (or continue) DAgger; returns the run folder. Each row of ``dagger.json``: the round, its beta, the
    episodes and labels it added and the data set's size; labels that needed a re-plan (count, the seconds
    those labels took, MILP attempts and accepted re-plans, episodes that ran out of re-plans); every label's
    seconds and the median of the others (ms); the local re-aims; the success of its mixed episodes; the
    learner's error against the labels on them; then the fit's validation error, kept epoch and seconds; the
    learner's success, robustness and median ms per step alone, each evaluation episode, and the seconds that
    took; the env steps flown so far (all labelled) and the wall clock of the collection and fits so far."""
    import torch

    scenario = load_scenario(config.scenario)
    run_dir = run_folder_path(config.out, config.runs_dir, f"dagger_{scenario.name}_s{config.seed}")
    check_output_folder(run_dir, "--out")
    rows = _start(config, run_dir)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # the learner's forward passes too (see baselines.bc.fit_policy)
    try:
        return _rounds(config, scenario, run_dir, rows)
    finally:
        torch.set_num_threads(threads)


def _rounds(config: DAggerConfig, scenario: Scenario, run_dir: Path, rows: list[dict[str, Any]]) -> Path:
    from baselines.policy import SB3Controller
    from impact_env.transport.gym_env import TransportEnv

    data = [ep for r in range(len(rows)) for ep in load_round(run_dir, r)]
    held_out: list[LabelledEpisode] = []
    if rows:
        data, held_out = _split_round0(config, data, rows[0]["episodes"])
    expert = None  # built (and planned, without a plan file) when the first round needs it
    env = TransportEnv(scenario, **(config.env_options or {}))
    elapsed = rows[-1]["wall_s"] if rows else 0.0
    for round_ in range(len(rows), config.rounds + 1):
        start = time.perf_counter()
        beta = config.beta(round_)
        if round_ == 0 and config.dataset_dir is not None:
            new = _dataset_round(config, scenario)
        else:
            last = _policy_folder(run_dir, round_ - 1)  # the previous round's policy (runs before: the folder's)
            learner = (SB3Controller(scenario, (last if last.is_dir() else run_dir) / "model.zip")
                       if round_ > 0 else None)
            rng = np.random.default_rng([config.seed, round_])
            count = config.initial_episodes if round_ == 0 else config.episodes_per_round
            expert = expert or _expert(config, scenario)
            new = []
            for k in range(count):
                new.append(labelled_episode(env, expert, episode_seed(config.seed, round_, k), learner, beta, rng))
        save_round(round_file(run_dir, round_), new)
        if round_ == 0:
            data, held_out = _split_round0(config, new, len(new))
        else:
            data = data + new
        row = _round_row(round_, beta, new, data + held_out)
        if not config.quiet:
            print(f"round {round_}/{config.rounds} (beta {beta:.3g}): {row['labels']} labels, "
                  f"{row['replan_labels']} needed a re-plan"
                  + (f" ({row['replan_label_s']:.2f} s of {row['label_s']:.2f} s labelling)"
                     if row["label_s"] is not None else "")
                  + f"; fitting on {sum(e.steps for e in data)} labels", flush=True)
        fitted = fit_policy(scenario, [(e.observations, e.labels) for e in data],
                            [(e.observations, e.labels) for e in held_out], epochs=config.epochs,
                            batch_size=config.batch_size, learning_rate=config.learning_rate,
                            ent_weight=config.ent_weight, seed=config.seed, net_arch=config.net_arch, quiet=True)
        row.update({"val_mse": fitted.val_mse, "kept_epoch": fitted.kept_epoch, "fit_s": fitted.wall_time_s,
                    "train_mse": fitted.history[fitted.kept_epoch - 1]["train_mse"]})
        folder = _policy_folder(run_dir, round_)
        folder.mkdir(parents=True, exist_ok=True)
        save_policy(fitted, folder, _meta(config, scenario, round_, rows + [row], fitted, len(data), len(held_out)))
        fitted.venv.close()
        trained = time.perf_counter()
        row.update(_evaluate(config, scenario, folder))
        row["eval_s"] = time.perf_counter() - trained
        row["env_steps"] = (rows[-1]["env_steps"] if rows else 0) + row["labels"]
        elapsed += trained - start
        row["wall_s"] = elapsed  # data collection and fits so far, without the evaluations
        rows.append(row)
        chosen = selected_round(rows)
        for name in ("model.zip", NORMALIZATION_FILE, "train.json"):  # the run's policy: the selected round's
            with atomic_path(run_dir / name) as tmp:
                shutil.copyfile(_policy_folder(run_dir, chosen) / name, tmp)
        (run_dir / LEGACY_NORMALIZATION_FILE).unlink(missing_ok=True)  # as save_policy: no stale pickle beside it
        write_atomic(run_dir / "dagger.json", json.dumps({"settings": config.settings(), "rounds": rows,
                                                          "selected_round": chosen}, indent=1))
        if not config.quiet:
            success = "-" if row["eval_success"] is None else f"{100 * row['eval_success']:.0f} %"
            val = "-" if row["val_mse"] is None else f"{row['val_mse']:.3g}"
            print(f"  validation error {val}, learner alone {success} of {config.eval_episodes}, "
                  f"{elapsed:.0f} s so far", flush=True)
    env.close()
    return run_dir


def _split_round0(config: DAggerConfig, data: list[LabelledEpisode],
                  first: int) -> tuple[list[LabelledEpisode], list[LabelledEpisode]]:
    """(training episodes, held-out ones): the held-out share of round 0's ``first`` episodes, as BC splits."""
    train0, held_out = split_episodes(data[:first], config.validation_share)
    return train0 + data[first:], held_out


def _meta(config: DAggerConfig, scenario: Scenario, round_: int, rows: list[dict[str, Any]], fitted: Any,
          episodes_train: int, episodes_validation: int) -> dict[str, Any]:
    """``train.json`` of the round's policy, with the keys ``impact-env run`` and ``bench`` read."""
    return {"algo": "ppo", "method": "DAgger", "normalized": True, "scenario": scenario.name,
            "scenario_fingerprint": scenario_fingerprint(scenario), "env_options": dict(config.env_options or {}),
            "round": round_, "rounds": config.rounds, "episodes_train": episodes_train,
            "episodes_validation": episodes_validation, "samples": fitted.samples, "multiagent": False,
            "settings": json.loads(json.dumps(config.settings())), "kept_epoch": fitted.kept_epoch,
            "zero_action_mse": fitted.zero_action_mse, "history": fitted.history,
            "dagger_rounds": [{k: v for k, v in r.items()} for r in rows]}
