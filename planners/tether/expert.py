"""The tether expert: plans with the exact planner, flies the pulls, stops the cargo in the goal and holds it.

    expert = TetherExpert(load_station("L"))
    obs, info = env.reset(seed=0); expert.reset(env)
    action = expert.act(obs, info)       # one command per robot (TetherEnv's MultiDiscrete action)

Each control step it reads the cargo's state, the robots' anchors and the tether events, follows the current
pull to its switch point (measured along the pull) and changes anchor ("make before break" when ``k >= 2``);
it asks the planner whether the pull still lands in the level it was meant for, and replans from the current
state when it does not (or when a tether snags, is blocked, snaps or arrives early); under ``reel`` and
``force`` it brakes a moving cargo at each switch. The last pull ends with the plan's hold schedule: the brake
tether is attached ahead and held, the pulling one is held at the braking distance, and until the cargo rests
the expert keeps a held tether against whatever motion is left. A failed anchor is excluded and the plan made
again from the current state (the planner keeps every other anchor's geometry); a robot that dropped out is
not used again. A plan handed in (``plan=``) is checked and flown. The steps in full:
``docs/planner_design.md#tether-expert``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import shapely

from impact_env.tether.core import ATTACH0, KEEP, RELEASE, hold_command
from impact_env.tether.station import Station, load_station
from planners.errors import PlannerError
from planners.tether.braking import BEHIND_COS, brake_anchor, braking_distance_m
from planners.tether.errors import TetherInfeasibleError
from planners.tether.plan import TetherPlan
from planners.tether.reachability import ReachabilityConfig, ReachabilityPlanner

STOPPED_MPS = 0.01  # the cargo counts as at rest below this speed (for the switch brakes)
MOVING_MPS = 0.03  # under inertia, a new pull starts only below this speed (else the expert brakes first)
SETTLE_MPS = 0.001  # in the goal, a held tether is kept against any motion faster than this, and a slower one
# that would carry the cargo out of the goal box before the episode ends
TROUBLE = ("snagged", "blocked", "snapped", "anchor_failed", "refused", "dropped_out")


@dataclass
class ExpertStats:
    replans: int = 0
    brakes: int = 0
    plan_ms: list[float] = field(default_factory=list)
    act_ms: list[float] = field(default_factory=list)
    infeasible: int = 0
    excluded_anchors: list[int] = field(default_factory=list)


class TetherExpert:
    """The tether controller (central form :meth:`act`, per-agent form :meth:`agent_action`).

    Args:
        station: the station the environment runs (or its name / path).
        plan: a plan to fly (e.g. ``TetherPlan.load(...)``), checked against the station
            (:meth:`TetherPlan.check`; a failing plan raises its :class:`TetherPlanCheckError`); planned from the
            observed start if None.
        config: the exact planner's options.
    """

    name = "expert"

    def __init__(self, station: Station | str, plan: TetherPlan | None = None,
                 config: ReachabilityConfig | None = None) -> None:
        self.station = station if isinstance(station, Station) else load_station(station)
        if plan is not None:
            if plan.station != self.station.name:
                raise PlannerError(f"the plan is for station {plan.station!r}, not {self.station.name!r}")
            plan.check(self.station)  # the reasons it is refused, if it fails
        self.base_planner = ReachabilityPlanner(self.station, config)
        self._planners: dict[frozenset, ReachabilityPlanner] = {frozenset(): self.base_planner}
        self.initial_plan = plan
        st = self.station
        self.n_robots, self.n_anchors = st.n_robots, st.n_anchors
        self.w = st.pull_speed_mps
        self.dt = st.control_period_s
        self.t_switch = st.switch_time_s
        self.horizon_steps = round(st.formula.horizon_s / self.dt)
        self.agent_index = {name: i for i, name in enumerate(st.robot_names)}
        self.agent_index.update({f"robot_{i}": i for i in range(st.n_robots)})
        self.reset()

    # ------------------------------------------------------------------------------------------ API
    def reset(self, env: Any = None, seed: int | None = None) -> None:
        """Start an episode; with ``env`` (the tether env) it reads ``k``, the fidelity (whether a released cargo
        drifts) and the version of the env's spaces (the hold command and flag of version 1)."""
        core = getattr(getattr(env, "unwrapped", env), "core", None)
        self.fidelity = core.fidelity if core is not None else "kinematic"
        self.drifts = self.fidelity in ("reel", "force")
        self.k = core.k if core is not None else self.station.k
        version = core.version if core is not None else 1
        self.block = self.n_anchors + (3 if version >= 1 else 2)
        self.hold = hold_command(self.n_anchors) if version >= 1 else None
        if core is not None:
            self.horizon_steps = core.horizon_steps
        self.excluded: set[int] = set()
        self.dropped: set[int] = set()
        self.planner = self.base_planner
        self.plan: TetherPlan | None = None
        self.index = 0
        self.mode = "pull"  # pull -> stop (the last pull's brake) -> rest (in the goal, held)
        self.braking: int | None = None  # the anchor of a switch brake
        self.brake_direction: np.ndarray | None = None
        self._last_speed: float | None = None
        self._end: np.ndarray | None = None  # the current pull's switch point
        self._stop_brake: int | None = None  # the brake anchor of the last pull
        self.stats = ExpertStats()
        self._cache: tuple[int, np.ndarray] | None = None
        self._pending_plan = self.initial_plan
        self._time_left_s = self.horizon_steps * self.dt  # until the episode ends (s), read from each observation

    def act(self, observation: np.ndarray, info: dict[str, Any] | None = None) -> np.ndarray:
        """One command per robot: 0 keep, 1 release, 2 + j attach to anchor j, the hold command."""
        t0 = time.perf_counter()
        obs = np.asarray(observation, dtype=float)
        expected = 4 + self.n_robots * self.block + self.n_anchors + 1
        if obs.shape != (expected,):
            raise ValueError(f"observation must have shape ({expected},) for station {self.station.name!r}, "
                             f"got {obs.shape}")
        step = round((1.0 - obs[-1]) * self.horizon_steps)
        self._time_left_s = max(0, self.horizon_steps - step) * self.dt
        x, v = obs[:2].copy(), obs[2:4].copy()
        held, pulling, holding, los = self._decode(obs)
        events = (info or {}).get("events", [])
        commands = [KEEP] * self.n_robots
        self._faults(events, held)
        los = los.copy()
        if self.excluded:
            los[list(self.excluded)] = False
        self._step(x, v, held, pulling, holding, los, events, commands)
        action = np.asarray(commands, dtype=np.int64)
        self._cache = (step, action)
        self.stats.act_ms.append(1e3 * (time.perf_counter() - t0))
        return action

    def agent_action(self, agent: str, observation: np.ndarray) -> int:
        """The command of one PettingZoo agent (its robot name, ``R1``, or ``robot_i`` in version 0) from its
        own observation (its block first)."""
        i = self.agent_index[agent]
        obs = np.asarray(observation, dtype=float)
        b = self.block
        blocks = obs[4: 4 + self.n_robots * b].reshape(self.n_robots, b)
        order = [i] + [r for r in range(self.n_robots) if r != i]
        central = blocks.copy()
        central[order] = blocks
        full = np.concatenate([obs[:4], central.reshape(-1), obs[4 + self.n_robots * b:]])
        step = round((1.0 - obs[-1]) * self.horizon_steps)
        if self._cache is None or self._cache[0] != step:
            return int(self.act(full)[i])  # act caches what it returns
        return int(self._cache[1][i])

    def report(self) -> dict[str, Any]:
        ms = np.asarray(self.stats.plan_ms) if self.stats.plan_ms else np.zeros(1)
        return {"replans": self.stats.replans, "brakes": self.stats.brakes, "infeasible": self.stats.infeasible,
                "planned_switches": None if self.plan is None else self.plan.switches,
                "excluded_anchors": sorted(self.excluded), "dropped_robots": sorted(self.dropped),
                "plan_ms": {"median": float(np.median(ms)), "max": float(np.max(ms))}}

    # ------------------------------------------------------------------------------------ internals
    def _decode(self, obs: np.ndarray) -> tuple[list[int | None], list[bool], list[bool], np.ndarray]:
        b, n = self.block, self.n_anchors
        held, pulling, holding = [], [], []
        for r in range(self.n_robots):
            block = obs[4 + r * b: 4 + (r + 1) * b]
            one_hot = block[:n]
            a = int(np.argmax(one_hot)) if one_hot.max() > 0.5 else None
            held.append(a)
            pulling.append(a is not None and block[n] == 0.0)
            holding.append(a is not None and b > n + 2 and block[n + 2] > 0.5)
        los0 = 4 + self.n_robots * b
        return held, pulling, holding, obs[los0: los0 + n] > 0.5

    def _faults(self, events: list[dict], held: list[int | None]) -> None:
        """Failed anchors leave the planner (a new one shares the others' geometry); dropped robots leave the
        fleet."""
        failed = {e["anchor"] for e in events if e["kind"] in ("anchor_failed", "refused")} - self.excluded
        for e in events:
            if e["kind"] == "dropped_out":
                self.dropped.add(e["robot"])
        if not failed:
            return
        self.excluded |= failed
        self.stats.excluded_anchors = sorted(self.excluded)
        key = frozenset(self.excluded)
        if key not in self._planners:
            self._planners[key] = self.base_planner.without(self.excluded)
        self.planner = self._planners[key]
        if self.braking in failed:
            self.braking = None
        if self._stop_brake in failed:
            self._stop_brake = None
        self.plan = None  # made again from the current state

    def _replan(self, x: np.ndarray, prefer: int | None = None) -> None:
        t0 = time.perf_counter()
        x = self.planner.inside_free(x)  # a cargo pressed against a wall is a hair outside the free space
        given, self._pending_plan = self._pending_plan, None
        try:
            self.plan = self._fly(given) if given is not None else self.planner.plan(x, prefer=prefer)
        except TetherInfeasibleError:
            self.stats.infeasible += 1
            self.plan = None  # nothing reaches the goal from here: keep still, try again next step
        except PlannerError:
            self.stats.infeasible += 1
            self.plan = None
        self.index = 0
        self._end = None
        self.mode = "pull"
        self._stop_brake = None
        self.stats.replans += 1
        self.stats.plan_ms.append(1e3 * (time.perf_counter() - t0))

    def _fly(self, plan: TetherPlan) -> TetherPlan:
        """A plan handed in, with the levels its pulls land in (what the closed loop checks each step)."""
        targets = []
        for p in plan.pulls:
            level = self.planner.level_of(p.end_m)
            targets.append(level if level is not None else 0)
        plan.stats = {**plan.stats, "targets": targets}
        return plan

    def _target_level(self, plan: TetherPlan) -> int:
        return int(plan.stats["targets"][self.index])

    def _robots_free(self, held: list[int | None]) -> list[int]:
        return [r for r, h in enumerate(held) if h is None and r not in self.dropped]

    def _step(self, x, v, held, pulling, holding, los, events, commands) -> None:
        trouble = any(e["kind"] in TROUBLE for e in events)
        if self.mode in ("stop", "rest"):
            if not trouble or self.mode == "rest":
                self._stop_and_hold(x, v, held, pulling, holding, los, commands)
                return
        if self.plan is not None and self.index < len(self.plan.pulls) and any(
                e["kind"] == "arrived" and e["anchor"] == self.plan.pulls[self.index].anchor for e in events):
            trouble = True  # released early, at the stop radius
        # braking at a switch (reel / force): hold the brake until the motion it opposes has stopped
        if self.braking is not None and self.brake_direction is not None:  # (set together)
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
            elif robot is not None and not pulling[robot] and self.hold is not None and not holding[robot]:
                commands[robot] = self.hold  # the brake holds from the moment it attaches
            return
        if self.plan is None or trouble:
            current = next((a for a, p in zip(held, pulling) if p and a not in self.excluded), None)
            self._replan(x, prefer=current)
            if self.plan is None:
                return
        if self.index >= len(self.plan.pulls):
            self.mode = "rest"
            self._stop_and_hold(x, v, held, pulling, holding, los, commands)
            return
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
        if holding[robot]:
            commands[robot] = ATTACH0 + a  # a held tether of the plan: reel in again
            return
        # the new tether pulls: let go of the previous anchors (make before break), keep the next one attaching
        last = self.index == len(self.plan.pulls) - 1
        upcoming = self.plan.pulls[self.index + 1].anchor if not last else self._stop_brake
        for r, h in enumerate(held):
            if r != robot and h is not None and h != upcoming:
                commands[r] = RELEASE
        if not last and upcoming in held and pulling[held.index(upcoming)]:
            commands[robot] = RELEASE  # the next tether pulls: hand over now
            self.index += 1
            self._end = None
            return
        # closed loop: from where the cargo is, does this pull still land in its level? where should it end?
        level = self._target_level(self.plan)
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
            if last and self._in_goal(x):
                self.mode = "stop"
                self._stop_and_hold(x, v, held, pulling, holding, los, commands)
            elif self.drifts and moving:
                self._brake(x, v, held, robot, los, commands, coast_s=0.0, advance=False)
            else:
                self._replan(x, prefer=None)
            return
        if last:
            self._approach(x, v, held, robot, los, commands, end)
            return
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

    # --------------------------------------------------------------------------------- the last pull
    def _approach(self, x, v, held, robot, los, commands, end) -> None:
        """The last pull toward ``end`` (the stop point): attach the brake ahead, then stop at the braking
        distance. Without inertia the pulling tether is held (or let go) within half a step of the stop point."""
        remaining = float(np.linalg.norm(end - x))
        speed = max(float(np.linalg.norm(v)), 0.5 * self.w)
        half_step = 0.5 * speed * self.dt
        if not self.drifts:
            if remaining <= half_step:
                commands[robot] = self.hold if self.hold is not None else RELEASE
                self.mode = "rest"
            return
        st = self.station
        stop_at = braking_distance_m(self.fidelity, speed, st.cargo.mass_kg, st.winch_force_limit_N, self.w)
        busy = [r for r, h in enumerate(held) if h is not None]
        spare = (self._robots_free(held) and len(busy) < self.k) or any(r != robot for r in busy)
        if not spare:
            # no second tether to brake with (one robot, or k = 1): the pulling robot itself trades its anchor
            # for the brake, so the cargo coasts t_switch on the pull's line before the brake holds
            if remaining - stop_at <= speed * self.t_switch + half_step:
                b = self._choose_brake(end, end - x, los)
                if b is not None and los[b]:
                    commands[robot] = ATTACH0 + b  # lets go of the pulling anchor first; held once attached
                    self._stop_brake = b
                    self.mode = "stop"
            return
        if self._stop_brake is not None and self._stop_brake in held and self.hold is not None:
            commands[held.index(self._stop_brake)] = self.hold  # the brake holds from the moment it attaches
        if self._stop_brake is None or self._stop_brake not in held:
            lead = speed * self.t_switch + 2.0 * speed * self.dt
            if remaining - stop_at <= lead:
                b = self._choose_brake(end, end - x, los)
                if b is not None and b not in held:
                    self._stop_brake = b
                    if not self._attach(b, held, commands, los, x, keep=robot, sight_needed=False):
                        self._stop_brake = None
        if remaining - stop_at <= half_step:
            commands[robot] = self.hold if self.hold is not None else RELEASE
            self.mode = "stop"

    def _choose_brake(self, point: np.ndarray, direction: np.ndarray, los: np.ndarray) -> int | None:
        """The plan's brake anchor if it still serves (not failed, in sight), else the best one from here."""
        hold = self.plan.hold if self.plan is not None else None
        if hold is not None and hold.brake_anchor is not None and hold.brake_anchor not in self.excluded \
                and los[hold.brake_anchor]:
            return hold.brake_anchor
        allowed = [a for a in range(self.n_anchors) if a not in self.excluded]
        return brake_anchor(self.station, point, direction, allowed, sight=los)

    def _drifts_out(self, x: np.ndarray, v: np.ndarray) -> bool:
        """Whether the cargo, drifting on at ``v`` from ``x``, would leave the goal box before the episode ends: the
        straight-line prediction of the impact expert's station keeping
        (:func:`planners.online.station_keeping.drift_margin`); the box is convex, so its end point decides."""
        x0, x1, y0, y1 = self.station.goal_box
        ex, ey = x + v * self._time_left_s
        return not (x0 <= ex <= x1 and y0 <= ey <= y1)

    def _in_goal(self, x: np.ndarray) -> bool:
        return self.planner.levels[0].distance(shapely.Point(*x)) < 1e-9

    def _stop_and_hold(self, x, v, held, pulling, holding, los, commands) -> None:
        """In the goal: every tether held, and a held tether kept against any motion left until the cargo rests,
        and against a creep too slow to count (below :data:`SETTLE_MPS`) that would still carry it out of the box
        before the episode ends. A cargo that came to rest outside the goal box (or was pushed out) is planned for
        again."""
        speed = float(np.linalg.norm(v))
        x0, x1, y0, y1 = self.station.goal_box
        inside_box = x0 <= x[0] <= x1 and y0 <= x[1] <= y1
        if not inside_box and speed < STOPPED_MPS:
            for r, h in enumerate(held):
                if h is not None:
                    commands[r] = RELEASE
            self._replan(x)
            return
        for r, (h, p, hd) in enumerate(zip(held, pulling, holding)):
            if h is not None and self.hold is not None and not hd:
                commands[r] = self.hold  # attaching or reeling: hold it
            elif h is not None and self.hold is None and p and not self.drifts:
                commands[r] = RELEASE  # version 0 without inertia: letting go stops the cargo
        if not self.drifts or self.hold is None or speed == 0.0:
            return
        if speed < SETTLE_MPS and not self._drifts_out(x, v):
            return  # a creep that stays in the box to the end
        vhat = v / speed
        pos = self.station.anchor_positions
        opposed = [h for h, p in zip(held, pulling) if h is not None and p
                   and float((pos[h] - x) @ vhat) / max(float(np.linalg.norm(pos[h] - x)), 1e-12) < BEHIND_COS]
        if opposed or any(h is not None and not p for h, p in zip(held, pulling)):
            return  # a held tether takes the motion up, or one is still attaching
        allowed = [a for a in range(self.n_anchors) if a not in self.excluded and a not in held]
        b = brake_anchor(self.station, x, v, allowed, sight=los)
        if b is None:
            return
        # re-attach the robot whose tether opposes least (the one the cargo moves toward)
        busy = [r for r, h in enumerate(held) if h is not None]
        free = self._robots_free(held)
        if free and len(busy) < self.k:
            commands[free[0]] = ATTACH0 + b
            return
        if busy:
            victim = max(busy, key=lambda r: float((pos[held[r]] - x) @ vhat))
            commands[victim] = ATTACH0 + b
            self.stats.brakes += 1

    # ---------------------------------------------------------------------------------- commands
    def _attach(self, anchor: int, held, commands, los, x, keep: int | None = None,
                sight_needed: bool = True) -> bool:
        """Attach a robot to ``anchor``: a free robot if ``k`` allows, else re-attach one (it lets go first)."""
        if not los[anchor]:
            if sight_needed:
                self._replan(x)
            return False
        free = self._robots_free(held)
        busy = [r for r, h in enumerate(held) if h is not None]
        if free and len(busy) < self.k:
            commands[free[0]] = ATTACH0 + anchor
            return True
        victims = [r for r in busy if r != keep and commands[r] != RELEASE]
        if victims:
            commands[victims[0]] = ATTACH0 + anchor
            return True
        return False

    def _brake(self, x, v, held, robot, los, commands, coast_s: float, advance: bool = True) -> None:
        """At a switch under inertia: trade the pulling tether for one toward an anchor opposite the motion,
        which pulls (or, in version 1, holds) when the coasting cargo reaches the switch point (``coast_s`` from
        now)."""
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
        ok = los & (dist > self.station.stop_radius_m + 0.2) & (cosines < BEHIND_COS)
        ok &= self.station.line_of_sight(there)
        if self.excluded:
            ok[list(self.excluded)] = False
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
    """The ``expert`` controller for a station (see :func:`planners.expert.make_expert`): a plan file is loaded,
    checked against the station and flown; one that fails its check is refused with the reasons."""
    return TetherExpert(station, plan=TetherPlan.load(plan) if plan else None)


__all__ = ["TetherExpert", "make_tether_expert"]
