"""The expert labelling the states another policy visits: one episode of DAgger's data (Ross et al. 2011).

    episode = labelled_episode(env, expert, seed=7, learner=controller, beta=0.25, rng=rng)

Each step, the expert is asked for its action in the observation the world is in, whoever put it there, and
that action is the step's label; then the executed action is the expert's with probability ``beta`` and the
learner's otherwise (the mixed policy of Ross et al., drawn per step). The expert is stateful: its impact
book reads the env's contact reports, the mission layer keeps the executed trace and the MPC its warm start,
so it is reset with the env and fed every observation and ``info`` of the episode in order, exactly as when it
flies itself (:class:`planners.expert.wrappers.ExpertActionInfo` does the same). It therefore tracks the
state the learner made, not the one its own plan expected: when the plan's predicted outcome from that state
leaves the tolerance, its mission layer re-plans the rest of the mission from it with the MILP
(:mod:`planners.online.mission`). Those labels are counted and timed here: a label "needed a re-plan" when the
expert's ``act`` for it ran a mission re-plan or a station-keeping trim (accepted or not: the MILP ran either
way). The local replanner's re-aims at planned impacts (Eq. 29), which happen on the expert's own episodes
too, are counted apart.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from impact_env.controllers import Controller
from planners.expert import Expert

__all__ = ["LabelledEpisode", "labelled_episode"]


@dataclass
class LabelledEpisode:
    """One episode of states and the expert's labels for them. T is the episode's steps."""

    seed: int
    """The env seed of the episode."""
    observations: np.ndarray
    """(T, obs) float32: the observation of each step, before its action."""
    labels: np.ndarray
    """(T, act) float32: the expert's action in each observation."""
    expert_acted: np.ndarray
    """(T,) bool: the executed action was the expert's (else the learner's)."""
    learner_actions: np.ndarray
    """(T, act) float32: the learner's action in each observation (NaN in the expert's own episodes)."""
    replan_labels: np.ndarray
    """(T,) bool: the label's ``act`` ran a mission re-plan or a station-keeping trim."""
    label_s: np.ndarray
    """(T,) float64: seconds each label took (the expert's ``act``)."""
    replan_attempts: int
    """Mission re-plans and trims the expert ran in the episode (its MILP calls)."""
    replans_accepted: int
    """Of those, the ones whose plan it then flew."""
    replan_cap_reached: bool
    """The expert ran out of re-plans (``MissionConfig.max_replans``): later labels could not re-plan."""
    local_replans: int
    """The local replanner's re-aims around planned impacts (Eq. 29)."""
    success: bool
    """The episode's final robustness was > 0."""
    robustness: float
    """The episode's final robustness (m)."""

    @property
    def steps(self) -> int:
        return len(self.observations)

    def arrays(self, prefix: str) -> dict[str, np.ndarray]:
        """The episode as named arrays (for ``np.savez``), each named ``<prefix><field>``."""
        return {prefix + f.name: np.asarray(getattr(self, f.name)) for f in fields(self)}

    @classmethod
    def from_arrays(cls, data: Any, prefix: str) -> LabelledEpisode:
        values = {f.name: data[prefix + f.name] for f in fields(cls)}
        for name in ("seed", "replan_attempts", "replans_accepted", "local_replans"):
            values[name] = int(values[name])
        for name in ("replan_cap_reached", "success"):
            values[name] = bool(values[name])
        values["robustness"] = float(values["robustness"])
        return cls(**values)


def _milp_calls(expert: Expert) -> tuple[int, int]:
    """(mission re-plans and trims run so far in the episode, of which accepted)."""
    mission = expert.mission
    if mission is None:
        return 0, 0
    records: list[Any] = list(mission.records)
    if mission.station is not None:
        records += mission.station.records
    return len(records), sum(r.status.startswith("accepted") for r in records)


def labelled_episode(env: Any, expert: Expert, seed: int, learner: Controller | None = None, beta: float = 1.0,
                     rng: np.random.Generator | None = None) -> LabelledEpisode:
    """Fly one episode of the mixed policy in ``env`` (a TransportEnv of the expert's scenario, possibly wrapped)
    with every visited state labelled by ``expert`` (see the module docstring). Without a ``learner`` the
    expert flies alone (``beta`` is then 1)."""
    if learner is not None and rng is None:
        raise ValueError("a mixed rollout needs rng for the per-step choice between the expert and the learner")
    obs, info = env.reset(seed=seed)
    expert.reset()
    if learner is not None:
        learner.reset(env, seed)
    observations, labels, learner_actions, acted, replanned, label_s = [], [], [], [], [], []
    done = False
    while not done:
        calls = _milp_calls(expert)[0]
        start = time.perf_counter()
        label = np.asarray(expert.act(obs, info), dtype=np.float32)
        label_s.append(time.perf_counter() - start)
        replanned.append(_milp_calls(expert)[0] > calls)
        if learner is None:
            own, by_expert = np.full_like(label, np.nan), True
        else:
            own = np.asarray(learner.act(obs, info), dtype=np.float32)
            by_expert = bool(rng.random() < beta)  # type: ignore[union-attr]  # checked above
        observations.append(np.asarray(obs, dtype=np.float32))
        labels.append(label)
        learner_actions.append(own)
        acted.append(by_expert)
        obs, _, terminated, truncated, info = env.step(label if by_expert else own)
        done = terminated or truncated
    attempts, accepted = _milp_calls(expert)
    mission = expert.mission
    capped = mission is not None and len(mission.records) >= mission.config.max_replans
    return LabelledEpisode(seed, np.array(observations), np.array(labels), np.array(acted), np.array(learner_actions),
                           np.array(replanned), np.array(label_s), attempts, accepted, bool(capped), expert.replans,
                           bool(info["is_success"]), float(info["robustness"]))
