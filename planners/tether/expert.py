"""The tether expert: plans with the exact planner, flies the pulls in the tether environments, replans.

    expert = TetherExpert(load_station("L"))
    obs, info = env.reset(seed=0); expert.reset(env)
    action = expert.act(obs, info)       # one command per robot (TetherEnv's MultiDiscrete action)

Each control step it reads the cargo's state, the robots' anchors and the tether events, follows the current
pull to its switch point (measured along the pull) and changes anchor ("make before break" when ``k >= 2``);
it asks the planner whether the pull still lands in the level it was meant for, and replans from the current
state when it does not (or when a tether snags, is blocked or arrives early); under ``reel`` and ``force`` it
brakes a moving cargo at each switch. It reads the fidelity level at :meth:`reset` but not the winches' real
speed: a mismatch in ``w`` is what it must absorb. The steps in full: ``docs/planner_design.md#tether-expert``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import shapely

from impact_env.tether.core import ATTACH0, KEEP, RELEASE
from impact_env.tether.station import Station, load_station
from planners.errors import PlannerError
from planners.tether.errors import TetherInfeasibleError
from planners.tether.plan import TetherPlan
from planners.tether.reachability import ReachabilityConfig, ReachabilityPlanner

BRAKE_COS = -0.5  # an anchor brakes when its direction is within 120 degrees of opposite to the motion
STOPPED_MPS = 0.01  # the cargo counts as at rest below this speed
MOVING_MPS = 0.03  # under inertia, a new pull starts only below this speed (else the expert brakes first)


@dataclass
class ExpertStats:
    replans: int = 0
    brakes: int = 0
    plan_ms: list[float] = field(default_factory=list)
    act_ms: list[float] = field(default_factory=list)
    infeasible: int = 0


class TetherExpert:
    """The tether controller (central form :meth:`act`, per-agent form :meth:`agent_action`).

    Args:
        station: the station the environment runs (or its name / path).
        plan: a plan to start from (e.g. ``TetherPlan.load(...)``); planned from the observed start if None.
        config: the exact planner's options.
    """

    name = "expert"

    def __init__(self, station: Station | str, plan: TetherPlan | None = None,
                 config: ReachabilityConfig | None = None) -> None:
        self.station = station if isinstance(station, Station) else load_station(station)
        if plan is not None and plan.station != self.station.name:
            raise PlannerError(f"the plan is for station {plan.station!r}, not {self.station.name!r}")
        self.planner = ReachabilityPlanner(self.station, config)
        self.initial_plan = plan
        st = self.station
        self.n_robots, self.n_anchors = st.n_robots, st.n_anchors
        self.k = st.k
        self.w = st.pull_speed_mps
        self.dt = st.control_period_s
        self.t_switch = st.switch_time_s
        self.horizon_steps = round(st.formula.horizon_s / self.dt)
        self.reset()

    # ------------------------------------------------------------------------------------------ API
    def reset(self, env: Any = None, seed: int | None = None) -> None:
        """Start an episode; with ``env`` (the tether env) it reads ``k`` and whether a released cargo drifts."""
        core = getattr(getattr(env, "unwrapped", env), "core", None)
        self.drifts = core is not None and core.fidelity in ("reel", "force")
        if core is not None:
            self.k = core.k
        self.plan: TetherPlan | None = None
        self.index = 0
        self.braking: int | None = None  # the anchor of a braking tether
        self.brake_direction: np.ndarray | None = None
        self._last_speed: float | None = None
        self._end: np.ndarray | None = None  # the current pull's switch point
        self.stats = ExpertStats()
        self._cache: tuple[int, np.ndarray] | None = None

    def act(self, observation: np.ndarray, info: dict[str, Any] | None = None) -> np.ndarray:
        """One command per robot: 0 keep, 1 release, 2 + j attach to anchor j."""
        t0 = time.perf_counter()
        obs = np.asarray(observation, dtype=float)
        expected = 4 + self.n_robots * (self.n_anchors + 2) + self.n_anchors + 1
        if obs.shape != (expected,):
            raise ValueError(f"observation must have shape ({expected},) for station {self.station.name!r}, "
                             f"got {obs.shape}")
        step = round((1.0 - obs[-1]) * self.horizon_steps)
        x, v = obs[:2].copy(), obs[2:4].copy()
        held, pulling, los = self._decode(obs)
        events = (info or {}).get("events", [])
        commands = [KEEP] * self.n_robots
        self._step(x, v, held, pulling, los, events, commands)
        action = np.asarray(commands, dtype=np.int64)
        self._cache = (step, action)
        self.stats.act_ms.append(1e3 * (time.perf_counter() - t0))
        return action

    def agent_action(self, agent: str, observation: np.ndarray) -> int:
        """The command of one PettingZoo agent (``robot_i``) from its own observation (its block first)."""
        i = int(agent.rsplit("_", 1)[1])
        obs = np.asarray(observation, dtype=float)
        b = self.n_anchors + 2
        blocks = obs[4: 4 + self.n_robots * b].reshape(self.n_robots, b)
        order = [i] + [r for r in range(self.n_robots) if r != i]
        central = blocks.copy()
        central[order] = blocks
        full = np.concatenate([obs[:4], central.reshape(-1), obs[4 + self.n_robots * b:]])
        step = round((1.0 - obs[-1]) * self.horizon_steps)
        if self._cache is None or self._cache[0] != step:
            self.act(full)
        return int(self._cache[1][i])

    def report(self) -> dict[str, Any]:
        ms = np.asarray(self.stats.plan_ms) if self.stats.plan_ms else np.zeros(1)
        return {"replans": self.stats.replans, "brakes": self.stats.brakes, "infeasible": self.stats.infeasible,
                "planned_switches": None if self.plan is None else self.plan.switches,
                "plan_ms": {"median": float(np.median(ms)), "max": float(np.max(ms))}}

    # ------------------------------------------------------------------------------------ internals
    def _decode(self, obs: np.ndarray) -> tuple[list[int | None], list[bool], np.ndarray]:
        b = self.n_anchors + 2
        held, pulling = [], []
        for r in range(self.n_robots):
            block = obs[4 + r * b: 4 + (r + 1) * b]
            one_hot = block[: self.n_anchors]
            a = int(np.argmax(one_hot)) if one_hot.max() > 0.5 else None
            held.append(a)
            pulling.append(a is not None and block[self.n_anchors] == 0.0)
        los0 = 4 + self.n_robots * b
        return held, pulling, obs[los0: los0 + self.n_anchors] > 0.5

    def _replan(self, x: np.ndarray, prefer: int | None = None) -> None:
        t0 = time.perf_counter()
        x = self.planner.inside_free(x)  # a cargo pressed against a wall is a hair outside the free space
        try:
            self.plan = self.planner.plan(x, prefer=prefer)
        except TetherInfeasibleError:
            self.stats.infeasible += 1
            self.plan = None  # nothing reaches the goal from here: keep still, try again next step
        self.index = 0
        self._end = None
        self.stats.replans += 1
        self.stats.plan_ms.append(1e3 * (time.perf_counter() - t0))

    def _target_level(self) -> int:
        return int(self.plan.stats["targets"][self.index])

    def _step(self, x, v, held, pulling, los, events, commands) -> None:
        trouble = any(e["kind"] in ("snagged", "blocked") for e in events)
        if self.plan is not None and self.index == len(self.plan.pulls) - 1 and \
                any(e["kind"] == "arrived" and e["anchor"] == self.plan.pulls[-1].anchor for e in events):
            self.index += 1  # the last pull ran to its anchor: it has carried the cargo through the goal box
            return
        if self.plan is not None and self.index < len(self.plan.pulls) and any(
                e["kind"] == "arrived" and e["anchor"] == self.plan.pulls[self.index].anchor for e in events):
            trouble = True  # released early, at the stop radius
        # braking at a switch (reel / force): hold the brake until the motion it opposes has stopped
        if self.braking is not None:
            robot = held.index(self.braking) if self.braking in held else None
            along = float(np.dot(v, self.brake_direction))
            speed = float(np.linalg.norm(v))
            slowing = self._last_speed is None or speed < self._last_speed
            self._last_speed = speed if robot is not None and pulling[robot] else None
            # let go once the motion it opposes has stopped, or once it no longer slows the cargo down
            if robot is None or (pulling[robot] and (along <= STOPPED_MPS or not slowing)):
                if robot is not None:
                    commands[robot] = RELEASE
                self.braking = None
                self._replan(x)
            return
        if self.plan is None or trouble:
            current = next((a for a, p in zip(held, pulling) if p), None)
            self._replan(x, prefer=current)
            if self.plan is None:
                return
        if self.index >= len(self.plan.pulls):
            return  # in the goal (or through it): nothing left to do
        pull = self.plan.pulls[self.index]
        a = pull.anchor
        robot = held.index(a) if a in held else None
        moving = float(np.linalg.norm(v)) > MOVING_MPS
        if robot is None:
            pulling_robot = next((r for r, (h, p) in enumerate(zip(held, pulling)) if p), None)
            if self.drifts and moving and pulling_robot is not None:
                self._brake(x, v, held, pulling_robot, los, commands, coast_s=0.0, advance=False)
                return  # a new tether on a moving cargo would keep the motion across it: brake first
            self._attach(a, held, commands, los, x)
            return
        if not pulling[robot]:
            return  # attaching: wait
        # the new tether pulls: let go of the previous anchors (make before break), keep the next one attaching
        upcoming = self.plan.pulls[self.index + 1].anchor if self.index + 1 < len(self.plan.pulls) else None
        for r, h in enumerate(held):
            if r != robot and h is not None and h != upcoming:
                commands[r] = RELEASE
        if upcoming is not None and upcoming in held and pulling[held.index(upcoming)]:
            commands[robot] = RELEASE  # the next tether pulls: hand over now
            self.index += 1
            self._end = None
            return
        # closed loop: from where the cargo is, does this pull still land in its level? where should it end?
        level = self._target_level()
        if level == 0 and self.planner.levels[0].distance(shapely.Point(*x)) < 1e-9:
            self.index += 1  # in the goal box
            return
        end = self._end
        if end is not None:  # keep the switch point while it is still ahead on the line to the anchor
            u = self.station.anchor_positions[a] - x
            u /= max(float(np.linalg.norm(u)), 1e-12)
            ahead = end - x
            if float(np.dot(ahead, u)) < -0.5 * self.w * self.dt or abs(ahead[0] * u[1] - ahead[1] * u[0]) > 0.05:
                end = None
        if end is None:
            end = self.planner.pull_end(x, a, level)
            self._end = end
        if end is None:  # off course: under inertia stop first, then plan from (nearly) rest
            if self.drifts and moving:
                self._brake(x, v, held, robot, los, commands, coast_s=0.0, advance=False)
            else:
                self._replan(x, prefer=None)
            return
        last = self.index == len(self.plan.pulls) - 1
        if last:
            return  # the last pull runs into the goal box; the task is to be in it once
        remaining = float(np.linalg.norm(end - x))
        nxt = self.plan.pulls[self.index + 1].anchor
        speed = max(float(np.linalg.norm(v)), 0.5 * self.w)
        if self.drifts:
            # the brake tether pulls t_switch after its attach; the released cargo coasts on the pull's line
            if remaining <= speed * self.t_switch + 0.5 * speed * self.dt:
                self._brake(x, v, held, robot, los, commands, coast_s=max(0.0, remaining / speed))
            return
        lead = speed * self.t_switch  # attach the next robot this far ahead of the switch point
        if self.k >= 2 and remaining <= lead + 0.5 * speed * self.dt and nxt not in held and los[nxt]:
            self._attach(nxt, held, commands, los, x, keep=robot)
        if remaining <= 0.5 * speed * self.dt and nxt not in held:
            self.index += 1
            self._end = None
            # re-attach this robot (it lets go of the old anchor first) and wait t_switch
            self._replan(x, prefer=None)
            if self.plan is not None and self.plan.pulls:
                first = self.plan.pulls[0].anchor
                commands[robot] = ATTACH0 + first if los[first] else RELEASE

    def _attach(self, anchor: int, held, commands, los, x, keep: int | None = None) -> None:
        """Attach a robot to ``anchor``: a free robot if ``k`` allows, else re-attach one (it lets go first)."""
        if not los[anchor]:
            self._replan(x)
            return
        free = [r for r, h in enumerate(held) if h is None]
        busy = [r for r, h in enumerate(held) if h is not None]
        if free and len(busy) < self.k:
            commands[free[0]] = ATTACH0 + anchor
        else:
            victims = [r for r in busy if r != keep]
            if victims:
                commands[victims[0]] = ATTACH0 + anchor

    def _brake(self, x, v, held, robot, los, commands, coast_s: float, advance: bool = True) -> None:
        """At a switch under inertia: trade the pulling tether for one toward an anchor opposite the motion,
        which pulls when the coasting cargo reaches the switch point (``coast_s`` from now)."""
        speed = float(np.linalg.norm(v))
        if advance:
            self.index += 1
            self._end = None
        if speed <= STOPPED_MPS:
            self._replan(x)
            return
        vhat = v / speed
        there = x + v * coast_s
        pos = self.station.anchor_positions
        d = pos - there
        dist = np.linalg.norm(d, axis=1)
        cosines = (d @ vhat) / np.maximum(dist, 1e-12)
        ok = los & (dist > self.station.stop_radius_m + 0.2) & (cosines < BRAKE_COS)
        ok &= self.station.line_of_sight(there)
        if not ok.any():
            commands[robot] = RELEASE
            self._replan(x + v * self.t_switch)
            return
        c = int(np.argmin(np.where(ok, cosines, np.inf)))
        commands[robot] = ATTACH0 + c  # lets go of the pulling anchor and attaches to the brake
        self.braking = c
        self.brake_direction = vhat
        self._last_speed = None
        self.stats.brakes += 1


def make_tether_expert(station: Station, plan: str | None = None, **_: Any) -> TetherExpert:
    """The ``expert`` controller for a station (see :func:`planners.expert.make_expert`)."""
    return TetherExpert(station, plan=TetherPlan.load(plan) if plan else None)


__all__ = ["TetherExpert", "make_tether_expert"]
