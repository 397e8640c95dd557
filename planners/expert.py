"""The expert controller: offline plan + online two-body replanner + impact-aware MPC (paper Sec. IV-VII).

    expert = Expert(load_scenario("corridor"))           # plans with the MILP planner (or pass plan=)
    obs, info = env.reset(seed=0); expert.reset()
    action = expert.act(obs, info)                          # the Gymnasium env's normalised action

Each control step, for each robot:

1. if one of its planned impacts is less than two grid intervals away (and the robot's previous impact is
   over), the replanner (Eq. 29) recomputes
   its pre- and post-impact segments from its current state: the object's state at the impact time is
   predicted from its observed position and velocity (free flight), the velocity the object must leave
   with is the one that takes it to where the plan needs it at its next impact (or the planned one after
   its last impact), and the circular impact model's closed-form inverse (Eq. 6-7) gives the contact
   position and the robot's pre- and post-impact velocities; after the impact it rejoins the plan;
2. otherwise the reference is the offline plan;
3. the MPC (Eq. 30-31) tracks the reference over its horizon, with the planned impact as a node
   constraint when it is inside the horizon and a keep-off constraint around the objects' predicted
   paths everywhere else.

The expert uses only what the environment exposes: the observation (positions, velocities, headings,
time left) and the episode's fixed facts from the scenario file (masses, radii, limits, restitution).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from impact_env.envs.core import ACTION_PER_ROBOT, OBS_PER_BODY
from impact_env.scenario import Scenario, load_scenario
from planners.errors import PlannerError
from planners.offline.sr_planner import PlannerConfig, plan_spatially_robust
from planners.online.impact_model import required_contact
from planners.online.mpc import AvoidSpec, FreeflyerMPC, ImpactSpec, MPCConfig
from planners.online.replanner import replan_around_impact, replan_segment
from planners.plan import Plan, PlannedImpact, Segment

KEEP_OFF_MARGIN_M = 0.03  # extra clearance around objects' discs away from planned impacts
REPLAN_INTERVALS = 2  # replanning starts this many grid intervals before an impact (after the previous one)
CONTACT_WINDOW_S = 0.5  # from this long before a pending impact the keep-off constraint is lifted
LATE_GRACE_S = 0.5  # a planned impact not yet observed is still approached this long after its time


@dataclass
class _Replanned:
    impact: PlannedImpact
    pre: Segment
    post: Segment


@dataclass
class ExpertStats:
    """Per-episode numbers: MPC solve times (ms, per robot per step), replans, MPC failures."""

    mpc_ms: list[float] = field(default_factory=list)
    act_ms: list[float] = field(default_factory=list)
    replans: int = 0
    mpc_failures: int = 0


class Expert:
    """The paper's planning and control stack as a policy for :class:`impact_env.envs.TransportEnv`.

    Args:
        scenario: the scenario (or its name/path) the environment runs.
        plan: an offline plan for it (e.g. ``Plan.load("plan.json")``); planned with the MILP if None.
        planner_config / mpc_config: options of the planner and of the MPC.
    """

    name = "expert"

    def __init__(self, scenario: Scenario | str, plan: Plan | None = None,
                 planner_config: PlannerConfig | None = None, mpc_config: MPCConfig | None = None) -> None:
        self.scenario = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
        sc = self.scenario
        if plan is None:
            plan = plan_spatially_robust(sc, planner_config)
        elif plan.scenario != sc.name:
            raise PlannerError(f"the plan is for scenario {plan.scenario!r}, not {sc.name!r}")
        plan.check(sc, tol=1e-5)
        self.plan = plan
        self.dt = sc.control_period_s
        self.horizon_steps = round(sc.formula.horizon_s / self.dt)
        self.grid_dt = min(s.duration_s for b in plan.bodies.values() for s in b.segments)
        self.names = [b.name for b in sc.bodies]
        self.robots = list(sc.robots)
        self.objects = list(sc.objects)
        self.mpc_config = mpc_config or MPCConfig(dt_s=self.dt)
        self.mpcs = {r.name: FreeflyerMPC(r, self.mpc_config, heading_ref=r.heading_rad) for r in self.robots}
        self.limits = np.array([[*r.thrust_limit_N, r.torque_limit_Nm] for r in self.robots])
        self.stats = ExpertStats()
        self._replanned: dict[str, _Replanned] = {}
        self._done: set[int] = set()  # indices into plan.impacts of the impacts observed
        self._cache: tuple[int, np.ndarray] | None = None

    # ------------------------------------------------------------------------------------------ API
    def reset(self, env: Any = None, seed: int | None = None) -> None:
        """Start a new episode: forget warm starts, replans and statistics."""
        for mpc in self.mpcs.values():
            mpc.reset()
        self.stats = ExpertStats()
        self._replanned = {}
        self._done = set()
        self._cache = None

    def act(self, observation: np.ndarray, info: dict[str, Any] | None = None) -> np.ndarray:
        """The central action (3 numbers per robot in [-1, 1]) for a TransportEnv observation."""
        start = time.perf_counter()
        obs = np.asarray(observation, dtype=float)
        expected = OBS_PER_BODY * len(self.names) + 1
        if obs.shape != (expected,):
            raise ValueError(f"observation must have shape ({expected},) for scenario {self.scenario.name!r}, "
                             f"got {obs.shape}")
        step = round((1.0 - obs[-1]) * self.horizon_steps)
        t = step * self.dt
        states = obs[:-1].reshape(len(self.names), OBS_PER_BODY)
        self._observe_impacts((info or {}).get("impacts", []))
        actions = [self._robot_action(i, robot, t, states) for i, robot in enumerate(self.robots)]
        action = np.clip(np.concatenate(actions), -1.0, 1.0).astype(np.float32)
        self._cache = (step, action)
        self.stats.act_ms.append(1e3 * (time.perf_counter() - start))
        return action

    def agent_action(self, agent: str, observation: np.ndarray) -> np.ndarray:
        """The action of one PettingZoo agent (robot name) from its own observation (own body first)."""
        idx = [r.name for r in self.robots].index(agent)
        obs = np.asarray(observation, dtype=float)
        bodies = obs[:-1].reshape(len(self.names), OBS_PER_BODY)
        order = [idx] + [i for i in range(len(self.names)) if i != idx]
        central = np.empty_like(bodies)
        central[order] = bodies
        step = round((1.0 - obs[-1]) * self.horizon_steps)
        if self._cache is None or self._cache[0] != step:
            self.act(np.append(central.reshape(-1), obs[-1]))
        return self._cache[1][ACTION_PER_ROBOT * idx: ACTION_PER_ROBOT * (idx + 1)]

    # ---------------------------------------------------------------------------------- internals
    def _observe_impacts(self, events: list[dict]) -> None:
        """Mark planned impacts as done when the env reports a contact of that robot and object near them."""
        for ev in events:
            pair = {ev["a"], ev["b"]}
            candidates = [(abs(imp.time_s - ev["time"]), k) for k, imp in enumerate(self.plan.impacts)
                          if k not in self._done and pair == {imp.robot, imp.object}
                          and abs(imp.time_s - ev["time"]) <= 0.5 * self.grid_dt]
            if candidates:
                self._done.add(min(candidates)[1])

    def _pending(self, name: str, t: float) -> list[PlannedImpact]:
        return [imp for k, imp in enumerate(self.plan.impacts)
                if imp.robot == name and k not in self._done and imp.time_s > t - LATE_GRACE_S]

    def _body_state(self, states: np.ndarray, name: str) -> np.ndarray:
        """[x, y, theta, vx, vy, omega] of a body from its observation row."""
        x, y, vx, vy, c, s, om = states[self.names.index(name)]
        return np.array([x, y, math.atan2(s, c), vx, vy, om])

    def _object_prediction(self, name: str, states: np.ndarray, t: float, t_target: float
                           ) -> tuple[np.ndarray, np.ndarray]:
        """Object position and velocity at ``t_target``: free flight from the observation, unless another
        planned impact on it comes first, in which case the plan's state just before ``t_target``."""
        pending = [i for i in self.plan.impacts_of(name) if t < i.time_s < t_target - 1e-9]
        if pending:
            body = self.plan.bodies[name]
            return body.position(t_target), body.velocity(t_target - 1e-6)
        s = self._body_state(states, name)
        return s[:2] + s[3:5] * (t_target - t), s[3:5].copy()

    def _desired_object_velocity(self, impact: PlannedImpact, position_at_impact: np.ndarray) -> np.ndarray:
        """Leave the impact so as to be where the plan needs the object at its next impact."""
        later = [i for i in self.plan.impacts_of(impact.object) if i.time_s > impact.time_s + 1e-9]
        if not later:
            return np.asarray(impact.object_velocity_after, float)
        nxt = min(later, key=lambda i: i.time_s)
        return (np.asarray(nxt.position) - position_at_impact) / (nxt.time_s - impact.time_s)

    def _replan(self, robot, t: float, state: np.ndarray, impact: PlannedImpact, states: np.ndarray
                ) -> _Replanned | None:
        obj = self.scenario.body(impact.object)
        x_o, v_o = self._object_prediction(impact.object, states, t, impact.time_s)
        v_des = self._desired_object_velocity(impact, x_o)
        contact = required_contact(x_o, v_o, v_des, robot.mass_kg, robot.radius_m, obj.mass_kg, obj.radius_m,
                                   self.scenario.restitution)
        if contact is None:
            return None
        t_rejoin = min(impact.time_s + self.grid_dt, self.plan.tf_s)
        if t_rejoin <= impact.time_s + 1e-9:
            t_rejoin = impact.time_s + self.grid_dt
        plan_body = self.plan.bodies[robot.name]
        pre, post = replan_around_impact(t, state[:2], state[3:5], impact.time_s, contact, t_rejoin,
                                         plan_body.position(t_rejoin), plan_body.velocity(t_rejoin),
                                         robot.velocity_bound_mps)
        self.stats.replans += 1
        return _Replanned(impact, pre, post)

    def _robot_action(self, index: int, robot, t: float, states: np.ndarray) -> np.ndarray:
        state = self._body_state(states, robot.name)
        name = robot.name
        pending = self._pending(name, t)
        nxt = min(pending, key=lambda i: i.time_s) if pending else None
        past = [i.time_s for i in self.plan.impacts if i.robot == name and i.time_s <= t + 1e-9 and i is not nxt]
        window_start = max([nxt.time_s - REPLAN_INTERVALS * self.grid_dt] + [p + self.dt for p in past]) if nxt else 0
        current = self._replanned.get(name)
        approaching = nxt is not None and t >= window_start - 1e-9
        if approaching and nxt.time_s > t + 1e-9:
            replanned = self._replan(robot, t, state, nxt, states)
            if replanned is not None:
                self._replanned[name] = current = replanned
        elif approaching:
            pass  # late: keep the last approach, continued straight at the contact velocity (see _reference)
        elif current is not None and t < current.post.t1_s:
            # after the impact: rejoin the plan from where the robot really is
            plan_body = self.plan.bodies[name]
            t1 = current.post.t1_s
            current.post = replan_segment(state[:2], state[3:5], plan_body.position(t1), plan_body.velocity(t1),
                                          t, t1, robot.velocity_bound_mps)
        elif current is not None:
            del self._replanned[name]
            current = None
        approaching = approaching and current is not None and current.impact is nxt

        n = self.mpc_config.horizon
        times = t + self.dt * np.arange(n + 1)
        reference = self._reference(name, times, current, approaching)
        impact_spec = None
        if approaching and current.pre.t1_s > t:
            k = round((current.pre.t1_s - t) / self.dt)
            if 1 <= k <= n:
                impact_spec = ImpactSpec(step=k, position=current.pre.control_points[-1],
                                         velocity_before=current.pre.velocity(current.pre.t1_s)[0],
                                         velocity_after=current.post.velocity(current.post.t0_s)[0])
        avoid = self._avoid(robot, t, times, states, nxt if approaching else None)
        result = self.mpcs[name].solve(state, reference, impact=impact_spec, avoid=avoid)
        self.stats.mpc_ms.append(result.solve_ms)
        if not result.success:
            self.stats.mpc_failures += 1
        return np.asarray(result.wrench, float) / self.limits[index]

    def _reference(self, name: str, times: np.ndarray, current: _Replanned | None, approaching: bool
                   ) -> np.ndarray:
        """[x, y, vx, vy] at the horizon's nodes: the replanned segments where they apply, else the plan.

        While an impact is still to come, the approach continues past the planned time straight at the
        contact velocity (a late contact is met at full speed, not braked for)."""
        body = self.plan.bodies[name]
        tf = self.plan.tf_s
        tt = np.minimum(times, tf)
        ref = np.hstack([body.position(tt), body.velocity(tt)])
        ref[times > tf, 2:] = 0.0
        if current is not None and approaching:
            pre = current.pre
            mask = times <= pre.t1_s + 1e-9
            ref[mask, :2] = pre.position(times[mask])
            ref[mask, 2:] = pre.velocity(times[mask])
            late = ~mask
            p_c, v_c = pre.control_points[-1], pre.velocity(pre.t1_s)[0]
            ref[late, :2] = p_c + np.outer(times[late] - pre.t1_s, v_c)
            ref[late, 2:] = v_c
        elif current is not None:
            seg = current.post
            mask = (times >= seg.t0_s - 1e-9) & (times <= seg.t1_s + 1e-9)
            if np.any(mask):
                ref[mask, :2] = seg.position(times[mask])
                ref[mask, 2:] = seg.velocity(times[mask])
        return ref

    def _avoid(self, robot, t: float, times: np.ndarray, states: np.ndarray, pending: PlannedImpact | None
               ) -> AvoidSpec | None:
        """Keep off the nearest object's predicted (free-flight) path, except around this robot's planned
        impacts on it and, while an impact is pending, from shortly before it on (the object's motion after
        the impact is the planned one, not the free flight)."""
        if not self.objects:
            return None
        me = self._body_state(states, robot.name)
        obj = min(self.objects, key=lambda o: np.linalg.norm(self._body_state(states, o.name)[:2] - me[:2]))
        s = self._body_state(states, obj.name)
        centers = s[:2] + np.outer(times - t, s[3:5])
        active = np.ones(len(times), dtype=bool)
        for imp in self.plan.impacts:
            if imp.robot == robot.name and imp.object == obj.name:
                active &= np.abs(times - imp.time_s) > CONTACT_WINDOW_S
        if pending is not None and pending.object == obj.name:
            active &= times < pending.time_s - CONTACT_WINDOW_S
        return AvoidSpec(centers=centers, min_distance=robot.radius_m + obj.radius_m + KEEP_OFF_MARGIN_M,
                         active=active)

    # ------------------------------------------------------------------------------------ reports
    def report(self) -> dict[str, Any]:
        """Planned-versus-executed numbers for the JSON summary of ``impact-env run``."""
        ms = np.asarray(self.stats.mpc_ms) if self.stats.mpc_ms else np.zeros(1)
        return {
            "planned_robustness": self.plan.robustness,
            "planned_impacts": [{"time": i.time_s, "robot": i.robot, "object": i.object,
                                 "position": list(i.position)} for i in self.plan.impacts],
            "replans": self.stats.replans,
            "mpc_failures": self.stats.mpc_failures,
            "mpc_ms": {"median": float(np.median(ms)), "p99": float(np.percentile(ms, 99))},
        }


    def plot_episode(self, result, path) -> None:
        """Fig. 6 of the paper for an episode run by ``impact_env.rollout.run_episode``."""
        from planners.plotting import plot_execution

        plot_execution(self.scenario, self.plan, result.times_s, result.positions, result.impacts,
                       result.robustness, path)


def make_expert(scenario: Scenario, plan: str | None = None, **_: Any) -> Expert:
    """Factory of the ``impact_env.controllers`` entry point: ``impact-env run SCENARIO --controller expert``.

    For a tether station it builds the tether expert (:mod:`planners.tether.expert`)."""
    from impact_env.station import Station

    if isinstance(scenario, Station):
        from planners.tether.expert import make_tether_expert

        return make_tether_expert(scenario, plan=plan)
    return Expert(scenario, plan=Plan.load(plan) if plan else None)
