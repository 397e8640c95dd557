"""The expert controller: offline plan + online two-body replanner + impact-aware MPC (paper Sec. IV-VII),
and what goes beyond the paper so that it still delivers when the world is not the model.

    expert = Expert(load_scenario("corridor"))           # plans with the MILP planner (or pass plan=)
    obs, info = env.reset(seed=0); expert.reset()
    action = expert.act(obs, info)                          # the Gymnasium env's normalised action

It composes the online layer (``planners/online/``): impact bookkeeping, identification, mission
replanning, reference selection (the replanner, Eq. 29, around each planned impact), safe segments and
keep-offs, and the MPC (Eq. 30-31). Each part beyond the paper is an option of :class:`ExpertConfig`;
``ExpertConfig.paper()`` is the paper's stack. The expert uses only what the environment exposes: the
observation, the env's documented ``info["impacts"]`` and the scenario file's fixed facts (masses, radii,
limits, the nominal restitution). What each part does: ``docs/expert_design.md``.
"""

from __future__ import annotations

import time
from dataclasses import KW_ONLY, InitVar, dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from impact_env.config_checks import (
    NOT_GIVEN,
    check_flag,
    check_instance,
    check_integer,
    check_number,
    fail,
    warn_deprecated,
)
from impact_env.transport.core import ACTION_PER_ROBOT, OBS_PER_BODY
from impact_env.transport.scenario import Body, Scenario, load_scenario
from planners.errors import PlannerError
from planners.offline.spatially_robust import PlannerConfig, plan_spatially_robust
from planners.online.bookkeeping import ImpactBook
from planners.online.identification import IdentificationConfig, ImpactIdentifier
from planners.online.keep_off import boundary_keep_off, objects_keep_off, robot_keep_off, segment_limits
from planners.online.mission import MissionConfig, MissionPlanner
from planners.online.mpc import FreeflyerMPC, MPCConfig
from planners.online.mpc_specs import AvoidSpec, HalfPlaneSpec
from planners.online.reference import ContactStrategy, PlanContact, ReferenceSelector, held_goal_regions
from planners.plan import Plan

if TYPE_CHECKING:
    from planners.tether.expert import TetherExpert


@dataclass(frozen=True)
class ExpertConfig:
    """Which parts of the expert run, and their margins. An optional part is its config, or None when off.

    The old keywords ``identification=True/False``, ``identification_config=`` and ``mission_replanning=`` are
    still accepted for one release, with a ``DeprecationWarning``: ``ExpertConfig(identification=False,
    mission_replanning=False)`` is ``ExpertConfig(identification=None, mission=None)``.
    """

    identification: IdentificationConfig | None = field(default_factory=IdentificationConfig)
    """Estimate restitution online and use it in the contact inverse (:mod:`planners.online.identification`);
    None: the scenario file's value."""
    mission: MissionConfig | None = field(default_factory=MissionConfig)
    """Monitor the plan's predicted outcome and re-plan the rest of the mission when it leaves the tolerance
    (:mod:`planners.online.mission`); None: no mission replanning."""
    safe_segments: bool = True
    """Replanned segments respect the world box, obstacles and other robots, and the MPC keeps off the other
    robots and the nearest wall or obstacle face; False: only the nearest object, as in the paper."""
    aim_final_position: bool = True
    """After an object's last planned impact, send it to its planned end position rather than only at its
    planned velocity (:class:`~planners.online.reference.PlanContact`)."""
    aim_held_goal_center: bool = True
    """With ``aim_final_position``: an object whose planned end position lies in the region of a goal held to
    the end of the task is aimed at the region's middle instead (:func:`planners.online.reference.final_aim`),
    so the drift its last impact's noise leaves has the region's half-width to use, not the plan's margin."""
    disc_offset: bool = True
    """Before each approach, fly the plan shifted to where a disc (not the planner's point) meets the object
    (:meth:`~planners.online.reference.ReferenceSelector._offset_toward`)."""
    object_margin_m: float = 0.03
    """Added to the radii in the MPC's keep-off from objects (m)."""
    robot_margin_m: float = 0.05
    """Added to the radii in the keep-off between robots (m)."""
    wall_margin_m: float = 0.03
    """Added to the radius in the keep-off from walls and obstacle faces (m)."""
    replan_intervals: int = 2
    """The local replanner starts this many grid intervals before an impact."""
    contact_window_s: float = 0.5
    """From this long before a pending impact the keep-off on its object is lifted (s)."""
    late_grace_s: float = 0.5
    """A planned impact not yet observed is still approached this long after its time (s)."""
    object_braking_share: float | None = None
    """When set, the MPC's keep-off from an object grows by the robot's stopping distance at its closing speed on
    it, with this share (in (0, 1]) of its largest deceleration (:func:`planners.online.keep_off.braking_margin`;
    on the object of the impact it approaches, only from above the plan's relative speed there): its horizon
    (1 s) is shorter than the time to stop from the top speed, and a robot on its way round an object or past
    another met it at up to 0.4 m/s (one_robot_two_objects seeds 23 and 47 at 0.02 m/s). None (the radii and
    ``object_margin_m`` alone), measured with ``MissionConfig.finer_grid_retry``: at 1.0 that cell's seeds 0-49
    delivered 36 episodes against 38 without, its seeds 50-149 73 against 71 (with ``kept_off_objects`` 2);
    from any closing speed 41 and 75, but obstacle_avoidance's pushes came slower (seed 31 lost; 0.5: worse;
    docs/robustness.md). Not a gain the noise of 150 episodes tells apart."""
    way_round: bool = False
    """A replanned approach whose straight way to its contact crosses the object's disc (the robot on the far side
    of it) gets round the object (:class:`planners.online.segment_qp.WayRound`: tangent rows at a bearing that
    turns to the contact's), instead of a segment through it that the MPC's keep-off deflects only 1 s ahead.
    False: the segment as before (the object is the MPC's keep-off only). Measured: docs/robustness.md."""
    kept_off_objects: int = 1
    """The MPC keeps off this many of the objects nearest the robot (:func:`planners.online.keep_off.objects_keep_off`,
    one keep-off row each). A robot on its way to one object past another can be nearer the one it is not
    heading for: one_robot_two_objects seed 43 at 0.02 m/s, R1 between O2 (just pushed) and O1 (its next
    contact) met O1 1.5 s early at 0.2 m/s and then O2. 1 (the paper's), measured: with 2, that cell's seeds
    50-149 delivered 71 episodes as with 1 (seeds 0-49, with the other two changes, 41 against 40), and
    four_robots at 0.02 m/s lost seed 46 of its 50 (docs/robustness.md)."""
    _: KW_ONLY
    identification_config: InitVar[Any] = NOT_GIVEN
    """Deprecated: ``identification``."""
    mission_replanning: InitVar[Any] = NOT_GIVEN
    """Deprecated: ``mission`` (None: off)."""

    @classmethod
    def paper(cls, **overrides: Any) -> ExpertConfig:
        """The paper's stack: local replanning at planned impacts only; ``overrides`` switch parts on."""
        return cls(**{"identification": None, "mission": None, "safe_segments": False, "aim_final_position": False,
                      "aim_held_goal_center": False, "disc_offset": False,
                      "object_braking_share": None, "kept_off_objects": 1, **overrides})

    def __post_init__(self, identification_config: Any, mission_replanning: Any) -> None:
        if isinstance(self.identification, bool):
            warn_deprecated(f"ExpertConfig(identification={self.identification}) is deprecated and will be removed "
                            "in 0.4.0: pass an IdentificationConfig, or None for off")
            object.__setattr__(self, "identification", IdentificationConfig() if self.identification else None)
        if identification_config is not NOT_GIVEN:
            warn_deprecated("ExpertConfig(identification_config=...) is deprecated and will be removed in 0.4.0: "
                            "pass ExpertConfig(identification=...)")
            if self.identification is not None:
                object.__setattr__(self, "identification", identification_config)
        if mission_replanning is not NOT_GIVEN:
            warn_deprecated(f"ExpertConfig(mission_replanning={mission_replanning!r}) is deprecated and will be "
                            "removed in 0.4.0: pass ExpertConfig(mission=MissionConfig(...)), or None for off")
            if not isinstance(mission_replanning, bool):
                fail("ExpertConfig.mission_replanning", mission_replanning, "True or False", PlannerError)
            if not mission_replanning:
                object.__setattr__(self, "mission", None)
            elif self.mission is None:
                object.__setattr__(self, "mission", MissionConfig())
        check_instance(self, "identification", PlannerError, IdentificationConfig, what="an IdentificationConfig",
                       none="off")
        check_instance(self, "mission", PlannerError, MissionConfig, what="a MissionConfig", none="off")
        for name in ("safe_segments", "aim_final_position", "aim_held_goal_center", "disc_offset", "way_round"):
            check_flag(self, name, PlannerError)
        for name in ("object_margin_m", "robot_margin_m", "wall_margin_m", "contact_window_s", "late_grace_s"):
            check_number(self, name, PlannerError, low=0)
        if self.object_braking_share is not None:
            check_number(self, "object_braking_share", PlannerError, low=0, low_open=True, high=1)
        check_integer(self, "replan_intervals", PlannerError, low=1)
        check_integer(self, "kept_off_objects", PlannerError, low=1)


@dataclass
class ExpertStats:
    """Per-episode numbers: MPC solve times (ms, per robot per step), act times (ms), replans, failures."""

    mpc_ms: list[float] = field(default_factory=list)
    act_ms: list[float] = field(default_factory=list)
    replans: int = 0
    mpc_failures: int = 0


class Expert:
    """The planning and control stack as a policy for :class:`impact_env.envs.TransportEnv`.

    Args:
        scenario: the scenario (or its name/path) the environment runs.
        plan: an offline plan for it (e.g. ``Plan.load("plan.json")``); planned with the MILP if None.
        planner_config: options of the planner (used when ``plan`` is None).
        mpc_config: options of the MPC.
        config: which parts run (:class:`ExpertConfig`; default all).
        strategy: the contact strategy of the reference selection (default: the SR plan's).
    """

    name = "expert"

    def __init__(self, scenario: Scenario | str, plan: Plan | None = None,
                 planner_config: PlannerConfig | None = None, mpc_config: MPCConfig | None = None,
                 config: ExpertConfig | None = None, strategy: ContactStrategy | None = None) -> None:
        self.scenario = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
        sc = self.scenario
        self.config = cfg = config or ExpertConfig()
        if plan is None:
            plan = plan_spatially_robust(sc, planner_config)
        elif plan.scenario != sc.name:
            raise PlannerError(f"the plan is for scenario {plan.scenario!r}, not {sc.name!r}")
        plan.check(sc, tol=1e-5)
        self.offline_plan = self.plan = plan
        self.dt = sc.control_period_s
        self.horizon_steps = round(sc.formula.horizon_s / self.dt)
        self.grid_dt = min(s.duration_s for b in plan.bodies.values() for s in b.segments)
        self.names = [b.name for b in sc.bodies]
        self._index = {n: i for i, n in enumerate(self.names)}
        self.robots = list(sc.robots)
        self.objects = list(sc.objects)
        self._robot_names = {r.name for r in self.robots}
        self._object_names = {o.name for o in self.objects}
        keep_off_rows = cfg.kept_off_objects + (len(self.robots) if cfg.safe_segments else 0)
        self.mpc_config = mpc_config or MPCConfig(dt_s=self.dt, keep_off_rows=keep_off_rows)
        self.mpcs = {r.name: FreeflyerMPC(r, self.mpc_config, heading_ref=r.heading_rad) for r in self.robots}
        self.limits = np.array([r.wrench_limits for r in self.robots])
        self.book = ImpactBook(plan.impacts, tolerance_s=0.5 * self.grid_dt)
        self.identifier = ImpactIdentifier(sc.restitution, {b.name: b.mass_kg for b in sc.bodies},
                                           frozenset(self._robot_names), frozenset(self._object_names),
                                           cfg.identification or IdentificationConfig(),
                                           {r.name: float(np.hypot(*r.wrench_limits[:2])) / r.mass_kg
                                            for r in self.robots})
        held = (held_goal_regions(sc) if cfg.aim_final_position and cfg.aim_held_goal_center else {})
        strategy = strategy or PlanContact(aim_final_position=cfg.aim_final_position, held=held)
        if plan.planner == "ir" and isinstance(strategy, PlanContact):
            from planners.online.contingency import CopyContact

            strategy = CopyContact(sc, fallback=strategy)  # the plan's copies as contingency plans
        self.selector = ReferenceSelector(plan, self.grid_dt, self.dt, strategy, cfg.replan_intervals,
                                          disc_offset=cfg.disc_offset, box=self._safe_box,
                                          way_round=cfg.way_round)
        self.mission = (MissionPlanner(sc, plan, cfg.mission, planner_config, cfg.aim_final_position,
                                       cfg.late_grace_s, identified=cfg.identification is not None, held=held)
                        if cfg.mission is not None else None)
        self.stats = ExpertStats()
        self._predicted: dict[str, tuple[int, np.ndarray]] = {}
        self._cache: tuple[int, np.ndarray] | None = None
        self._cache_obs: np.ndarray | None = None  # the observation the cached action is for
        self._step_objects: tuple[int, np.ndarray, dict[str, np.ndarray]] | None = None
        # per-episode constants of every step: the horizon's node offsets (s); per robot, how far it can get
        # within a replanned segment (m, at its velocity bound) and its largest acceleration (m/s^2)
        self._node_index = np.arange(self.mpc_config.horizon + 1)
        self._node_offsets = self.dt * self._node_index
        self._segment_reach = {r.name: float(np.hypot(*(r.velocity_bound_mps or (1.0, 1.0))))
                               * self.grid_dt * (cfg.replan_intervals + 1) for r in self.robots}
        self._a_max = {r.name: float(np.hypot(*r.wrench_limits[:2])) / r.mass_kg for r in self.robots}

    # ------------------------------------------------------------------------------------------ API
    def reset(self, env: Any = None, seed: int | None = None) -> None:
        """Start a new episode: forget warm starts, replans, estimates, statistics; fly the offline plan."""
        for mpc in self.mpcs.values():
            mpc.reset()
        self.stats = ExpertStats()
        self._set_plan(self.offline_plan, set())
        self.book.reset()
        self.identifier.reset()
        self.selector.reset()
        if self.mission is not None:
            self.mission.reset(self.offline_plan)
        self._predicted = {}
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
        cached_obs = self._cache_obs
        if (self._cache is not None and cached_obs is not None and self._cache[0] == step
                and np.array_equal(cached_obs, obs)):
            return self._cache[1].copy()  # the same observation again (e.g. PettingZoo agents, then act)
        t = step * self.dt
        rows = obs[:-1].reshape(len(self.names), OBS_PER_BODY)
        states = np.empty((len(self.names), 6))  # [x, y, theta, vx, vy, omega] per body
        states[:, 0:2], states[:, 2], states[:, 3:5], states[:, 5] = \
            rows[:, 0:2], np.arctan2(rows[:, 5], rows[:, 4]), rows[:, 2:4], rows[:, 6]
        events = (info or {}).get("impacts", [])
        completed = self.book.observe(events, self._robot_names, self._object_names)
        if self.config.identification is not None:
            self.identifier.observe(events)
        if self.mission is not None:
            new = self.mission.step(t, states, self._index, self.plan, self.book, bool(completed), self._model)
            if new is not None:
                plan, done = new
                self._set_plan(plan, done)
        actions = [self._robot_action(i, robot, t, step, states) for i, robot in enumerate(self.robots)]
        action = np.minimum(np.maximum(np.concatenate(actions), -1.0), 1.0).astype(np.float32)  # np.clip
        self._cache = (step, action)
        self._cache_obs = obs
        self.stats.replans = self.selector.replans
        self.stats.act_ms.append(1e3 * (time.perf_counter() - start))
        return action

    def agent_action(self, agent: str, observation: np.ndarray, info: dict[str, Any] | None = None) -> np.ndarray:
        """The action of one PettingZoo agent (robot name) from its own observation (own body first) and, for
        identification, its ``info`` (each agent's info carries the same contact reports; the first agent
        to ask in a step computes every robot's action)."""
        idx = [r.name for r in self.robots].index(agent)
        obs = np.asarray(observation, dtype=float)
        bodies = obs[:-1].reshape(len(self.names), OBS_PER_BODY)
        order = [idx] + [i for i in range(len(self.names)) if i != idx]
        central = np.empty_like(bodies)
        central[order] = bodies
        step = round((1.0 - obs[-1]) * self.horizon_steps)
        if self._cache is None or self._cache[0] != step:
            action = self.act(np.append(central.reshape(-1), obs[-1]), info)  # computed, and cached as it is
        else:
            action = self._cache[1]
        return action[ACTION_PER_ROBOT * idx: ACTION_PER_ROBOT * (idx + 1)]

    # ---------------------------------------------------------------------------------- internals
    def _set_plan(self, plan: Plan, done: set[int]) -> None:
        self.plan = plan
        self.book.replace(plan.impacts, done)
        self.selector.set_plan(plan)
        self._impacts_by_robot = {r.name: [(k, i) for k, i in enumerate(plan.impacts) if i.robot == r.name]
                                  for r in self.robots}
        self._impact_times_of = {o.name: [i.time_s for i in plan.impacts_of(o.name)] for o in self.objects}

    def _safe_box(self, robot: Body) -> tuple[float, float, float, float]:
        """The box a robot's centre stays in: the world box shrunk by its radius and the wall margin."""
        xmin, xmax, ymin, ymax = self.scenario.world_box
        r = robot.radius_m + self.config.wall_margin_m
        return xmin + r, xmax - r, ymin + r, ymax - r

    def _model(self, robot: str, obj: str) -> tuple[float, tuple[float, float]]:
        """(restitution, (m_robot, m_object)) of the pair: identified, or the scenario file's."""
        if self.config.identification is not None:
            return self.identifier.restitution_for(robot, obj), self.identifier.masses_for(robot, obj)
        sc = self.scenario
        return sc.restitution, (sc.body(robot).mass_kg, sc.body(obj).mass_kg)

    def _object_prediction(self, states: np.ndarray, t: float):
        plan, sampler, impact_times = self.plan, self.selector.sampler, self._impact_times_of

        def predict(name: str, t_target: float) -> tuple[np.ndarray, np.ndarray]:
            """Object position and velocity at ``t_target``: free flight from the observation, unless another
            planned impact on it comes first, in which case the plan's state just before ``t_target``."""
            times = impact_times.get(name)
            if times is None:
                times = [i.time_s for i in plan.impacts_of(name)]
            if any(t < time_s < t_target - 1e-9 for time_s in times):
                return sampler.position(name, t_target), sampler.velocity(name, t_target - 1e-6)
            s = states[self._index[name]]
            return s[:2] + s[3:5] * (t_target - t), s[3:5].copy()

        return predict

    def _robot_action(self, index: int, robot: Body, t: float, step: int, states: np.ndarray) -> np.ndarray:
        name = robot.name
        state = states[self._index[name]]
        cfg = self.config
        pending = [imp for k, imp in self._impacts_by_robot[name]
                   if k not in self.book.done and imp.time_s > t - cfg.late_grace_s]
        nxt = min(pending, key=lambda i: i.time_s) if pending else None
        past = [i.time_s for _, i in self._impacts_by_robot[name] if i.time_s <= t + 1e-9 and i is not nxt]
        n = self.mpc_config.horizon
        times = t + self._node_offsets
        limits = None
        if cfg.safe_segments:
            reach = self._segment_reach[name]
            # only robots that either robot could reach within a replanned segment can meet it
            others = [self._planned_path(o.name) for o in self.robots if o.name != name
                      and np.hypot(*(states[self._index[o.name]][:2] - state[:2])) < 2 * reach + 2 * robot.radius_m]
            limits = segment_limits(self.scenario, robot, state[:2], others,
                                    2 * robot.radius_m + cfg.robot_margin_m, reach)
        ref = self.selector.robot_reference(robot, self.scenario.body, t, state, nxt, past, times,
                                            self._object_prediction(states, t), self._model, limits)
        object_states = self._object_states(step, states)
        keep_off: list[AvoidSpec | HalfPlaneSpec | None] = list(objects_keep_off(
            robot, self.objects, cfg.kept_off_objects, t, times, state[:2], object_states, self.plan.impacts,
            ref.approaching, cfg.object_margin_m, cfg.contact_window_s, state[3:5],
            None if cfg.object_braking_share is None else cfg.object_braking_share * self._a_max[name]))
        if cfg.safe_segments:
            a_max = self._a_max[name]
            speed = float(np.hypot(*state[3:5]))
            reach = speed * n * self.dt + 0.5 * a_max * (n * self.dt) ** 2  # how far it can get in the horizon
            for other in self.robots:
                if other.name != name:
                    centers = self._other_centers(other.name, step, states, n)
                    d = centers - state[:2]
                    gap = float(np.hypot(d[:, 0], d[:, 1]).min())
                    if gap < 2 * reach + robot.radius_m + other.radius_m + cfg.robot_margin_m:
                        keep_off.append(robot_keep_off(robot, other, centers, cfg.robot_margin_m))
            wall = boundary_keep_off(self.scenario, robot, state[:2], n + 1, reach, cfg.wall_margin_m)
            if wall is not None and not self._contact_beyond(wall, name, ref):
                keep_off.append(wall)
        avoid = [a for a in keep_off if a is not None]
        result = self.mpcs[name].solve(state, ref.reference, impact=ref.impact_spec, avoid=avoid or None)
        self._predicted[name] = (step, result.predicted[:, 0:2])
        self.stats.mpc_ms.append(result.solve_ms)
        if not result.success:
            self.stats.mpc_failures += 1
        return np.asarray(result.wrench, float) / self.limits[index]

    def _object_states(self, step: int, states: np.ndarray) -> dict[str, np.ndarray]:
        """name -> [x, y, vx, vy] of every object at this step (the same for every robot: made once)."""
        if self._step_objects is None or self._step_objects[0] != step or self._step_objects[1] is not states:
            self._step_objects = (step, states, {o.name: states[self._index[o.name]][[0, 1, 3, 4]]
                                                 for o in self.objects})
        return self._step_objects[2]

    def _contact_beyond(self, wall, name: str, ref) -> bool:
        """True if the robot approaches a contact that ``wall`` (a keep-off half-plane) would keep it from: an
        impact-robust plan's copy for an object state near a wall can put the disc's contact within its
        radius and margin of the wall (the planner's copies are points). The robot then approaches without the
        wall keep-off and may touch the wall; held off it, it meets the object early and from another side
        (``docs/expert_design.md#flying-an-impact-robust-plan``)."""
        current = self.selector.replanned.get(name)
        if ref.approaching is None or current is None or current.impact is not ref.approaching:
            return False
        contact = current.pre.control_points[-1]
        return bool(np.asarray(wall.normals, float) @ contact < float(wall.offsets) - 1e-9)

    def _planned_path(self, name: str):
        """Callable times -> (N, 2): robot ``name``'s planned centres, with its replanned segments."""
        sampler, replanned, tf = self.selector.sampler, self.selector.replanned, self.selector.tf
        # the replanner can ask twice for the same times (the closed form's check, then the QP's rows about the
        # same curve); the path is fixed while this step's other robot is planned, so answers are kept
        seen: dict[bytes, np.ndarray] = {}

        def path(times: np.ndarray) -> np.ndarray:
            key = times.tobytes()
            out = seen.get(key)
            if out is not None:
                return out
            out = sampler.positions(name, np.minimum(times, tf))
            current = replanned.get(name)
            if current is not None:
                for seg in (current.pre, current.post):
                    mask = (times >= seg.t0_s) & (times <= seg.t1_s)
                    if mask.any():
                        out[mask] = seg.position(times[mask])
            seen[key] = out
            return out

        return path

    def _other_centers(self, name: str, step: int, states: np.ndarray, n: int) -> np.ndarray:
        """Another robot's predicted centres at the horizon's nodes: its latest MPC prediction shifted to this
        step (held at its end), or its current position if it has none yet."""
        if name in self._predicted:
            at, pred = self._predicted[name]
            shift = step - at
            idx = np.minimum(np.maximum(self._node_index[:n + 1] + shift, 0), len(pred) - 1)
            return pred[idx]
        return np.tile(states[self._index[name]][:2], (n + 1, 1))

    # ------------------------------------------------------------------------------------ reports
    def report(self) -> dict[str, Any]:
        """Planned-versus-executed numbers for the JSON summary of ``impact-env run``."""
        ms = np.asarray(self.stats.mpc_ms) if self.stats.mpc_ms else np.zeros(1)
        act = np.asarray(self.stats.act_ms) if self.stats.act_ms else np.zeros(1)
        out = {
            "planned_robustness": self.offline_plan.robustness,
            "planner": self.offline_plan.planner,
            "planned_impacts": [{"time": i.time_s, "robot": i.robot, "object": i.object,
                                 "position": list(i.position)} for i in self.plan.impacts],
            "replans": self.selector.replans,
            "mpc_failures": self.stats.mpc_failures,
            "mpc_ms": {"median": float(np.median(ms)), "p99": float(np.percentile(ms, 99))},
            "act_ms": {"median": float(np.median(act)), "p99": float(np.percentile(act, 99))},
            "unplanned_contacts": dict(sorted(self.book.unplanned.items())),
            "config": {"identification": self.config.identification is not None,
                       "mission_replanning": self.config.mission is not None,
                       "safe_segments": self.config.safe_segments,
                       "aim_final_position": self.config.aim_final_position,
                       "aim_held_goal_center": self.config.aim_held_goal_center,
                       "disc_offset": self.config.disc_offset},
        }
        if self.offline_plan.planner == "ir":
            # the residual final velocity the plan accounts for, per object and axis (its final box)
            out["planned_delta_mps"] = self.offline_plan.delta_mps
            out["tolerated_final_velocity_mps"] = {name: list(f.final_box_mps)
                                                   for name, f in self.offline_plan.funnels.items()}
        if self.config.identification is not None:
            out["identification"] = self.identifier.report()
        if self.mission is not None:
            out["mission"] = self.mission.report()
        return out

    @property
    def replans(self) -> int:
        return self.selector.replans

    def plot_episode(self, result, path) -> None:
        """Fig. 6 of the paper for an episode run by ``impact_env.rollout.run_episode``."""
        from planners.plan.plotting import plot_execution

        plot_execution(self.scenario, self.plan, result.times_s, result.positions, result.impacts,
                       result.robustness, path)


def make_expert(scenario: Scenario, plan: str | None = None, **_: Any) -> Expert | TetherExpert:
    """Factory of the ``impact_env.controllers`` entry point: ``impact-env run SCENARIO --controller expert``.

    For a tether station it builds the tether expert (:mod:`planners.tether.expert`)."""
    from impact_env.tether.station import Station

    if isinstance(scenario, Station):
        from planners.tether.expert import make_tether_expert

        return make_tether_expert(scenario, plan=plan)
    return Expert(scenario, plan=Plan.load(plan) if plan else None)


__all__ = ["Expert", "ExpertConfig", "ExpertStats", "make_expert"]
