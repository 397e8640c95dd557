"""The episode logic shared by the tether Gymnasium and PettingZoo environments.

One :class:`TetherCore` owns a station, the pymunk :class:`~impact_env.tether.physics.TetherWorld` (rebuilt on
every reset), the online STL monitor, the fleet's rules and the episode's faults. The environment classes only
translate its inputs and outputs into their APIs.

Commands, per robot and step, processed in robot order: ``0`` keep, ``1`` release (at once), ``2 + j`` attach to
anchor ``j`` (the tether pulls ``t_switch`` later; a robot holding another anchor lets go of it first), and in
version 1 ``n_anchors + 2`` hold (the robot's winch stops reeling and brakes; attaching again to the anchor it
holds reels in again). An attach is REJECTED, the robot keeping what it had and ``info["rejected"]`` saying why,
when the anchor is not in line of sight of the cargo centre, the cargo is already inside the anchor's stop
radius, another robot holds the anchor, ``k`` other robots already hold anchors (pulling or attaching), or the
robot has dropped out; a hold of a robot that holds no tether is rejected too. Attaching to the anchor a robot
already reels in on is a keep. A command that is not an integer in ``0 .. n_commands - 1`` (or NaN, or the wrong
number of commands) raises :class:`~impact_env.errors.ActionError`: no rule can make sense of it. The rewards
and ``info``: see :class:`TetherCore`.
"""

from __future__ import annotations

import math
from typing import Any, cast

import numpy as np

from impact_env.env_shell import check_can_step, clip_to_space, time_left
from impact_env.errors import ActionError, EnvConfigError
from impact_env.stl import parse
from impact_env.tether.faults import FaultConfig, FaultSchedule
from impact_env.tether.physics import FIDELITIES, TetherWorld
from impact_env.tether.sight import SightCache
from impact_env.tether.station import CARGO, DRIFT, Station, load_station
from impact_env.tether.task_monitor import HoldMonitor, task_monitor

REWARD_MODES = ("dense", "sparse")
KEEP, RELEASE, ATTACH0 = 0, 1, 2
VERSIONS = (0, 1)


def hold_command(n_anchors: int) -> int:
    """The hold command of a station with ``n_anchors`` anchors (version 1): the last one."""
    return ATTACH0 + n_anchors


class TetherCore:
    """Station + tether physics + STL monitor + fleet rules + faults: reset, apply commands, observe.

    Reward: ``"dense"`` (default) the per-step increment of the online robustness estimate of the task (the trace
    so far with its last sample held), so an episode's rewards sum to its final robustness; ``"sparse"`` the
    final robustness on the last step. Both subtract ``energy_penalty`` times the step's winch work (J). The
    robustness is clipped to +- :attr:`robustness_limit_m` (no predicate's can exceed it), so a constant task
    (``G[0,600] false``) gives finite rewards; the sign, hence ``is_success``, is unchanged.

    Args:
        station: a Station, a shipped station name or a path to a TOML file.
        fidelity: ``"kinematic"`` (default), ``"reel"`` or ``"force"`` (see :mod:`impact_env.tether.physics`).
        reward_mode: ``"dense"`` or ``"sparse"``.
        energy_penalty: reward cost per joule of winch work (>= 0).
        pull_speed_mps: the winches' actual ``w`` (default the station's): a mismatch for a planner.
        max_active: ``k`` for this environment (default the station's), 1 .. number of robots.
        initial_position_noise_m: the cargo starts uniformly within this radius of its start (disc kept inside).
        faults: a :class:`~impact_env.tether.faults.FaultConfig`, a dict of its fields, or None.
        version: 1 (the hold task by default, the hold command, the holding flag in the observation) or 0 (the
            ``-v0`` environments: a station whose task is its default flies the reach task instead).
    """

    def __init__(self, station: Station | str, fidelity: str = "kinematic", reward_mode: str = "dense",
                 energy_penalty: float = 0.0, pull_speed_mps: float | None = None, max_active: int | None = None,
                 initial_position_noise_m: float = 0.0, faults: FaultConfig | dict | None = None,
                 version: int = 1) -> None:
        self.station = station if isinstance(station, Station) else load_station(station)
        st = self.station
        if fidelity not in FIDELITIES:
            raise EnvConfigError(f"fidelity must be one of {FIDELITIES}, got {fidelity!r}")
        if reward_mode not in REWARD_MODES:
            raise EnvConfigError(f"reward_mode must be one of {REWARD_MODES}, got {reward_mode!r}")
        for name, value, most in (("energy_penalty", energy_penalty, 1e6),
                                  ("initial_position_noise_m", initial_position_noise_m, 1e4)):
            if isinstance(value, bool) or not (isinstance(value, (int, float)) and math.isfinite(value)
                                               and 0 <= value <= most):
                raise EnvConfigError(f"{name} must be a finite number in [0, {most:g}], got {value!r}")
        if pull_speed_mps is not None and (isinstance(pull_speed_mps, bool) or not (
                isinstance(pull_speed_mps, (int, float)) and math.isfinite(pull_speed_mps) and pull_speed_mps > 0)):
            raise EnvConfigError(f"pull_speed_mps must be a finite number > 0 or None, got {pull_speed_mps!r}")
        if max_active is not None and (isinstance(max_active, bool) or not isinstance(max_active, int)
                                       or not 1 <= max_active <= st.n_robots):
            raise EnvConfigError(f"max_active must be an integer in 1..{st.n_robots} (the station's robots) or None, "
                                 f"got {max_active!r}")
        if version not in VERSIONS:
            raise EnvConfigError(f"version must be one of {VERSIONS}, got {version!r}")
        self.faults = FaultConfig.of(faults)
        if self.faults is not None and self.faults.robot_dropouts >= st.n_robots:
            raise EnvConfigError(f"FaultConfig.robot_dropouts must be < the station's {st.n_robots} robots, got "
                                 f"{self.faults.robot_dropouts}")
        self.version = version
        self.fidelity = fidelity
        self.reward_mode = reward_mode
        self.energy_penalty = float(energy_penalty)
        self.pull_speed_mps = st.pull_speed_mps if pull_speed_mps is None else float(pull_speed_mps)
        self.k = st.k if max_active is None else max_active
        self.initial_position_noise_m = float(initial_position_noise_m)
        spread = self.faults.winch_speed_error[1] if self.faults and self.faults.winch_speed_error else 0.0
        self.slowest_winch_mps = self.pull_speed_mps * (1.0 - spread)
        self.fastest_winch_mps = self.pull_speed_mps * (1.0 + spread)
        self._check_rates()
        self.task = st.reach_task if version == 0 and st.task == st.default_task else st.task

        self.n_robots = st.n_robots
        self.n_anchors = st.n_anchors
        self.hold_command = hold_command(self.n_anchors) if version >= 1 else None
        self.n_commands = self.n_anchors + (3 if version >= 1 else 2)
        self.dt_s = st.control_period_s
        self.monitor = task_monitor(parse(self.task), st.region_map(), self.dt_s)
        self.horizon_steps = self.monitor.horizon_steps
        self._pair_monitor = isinstance(self.monitor, HoldMonitor)
        # per robot: anchor one-hot, attach time left (fraction), tether length, and in v1 the holding flag
        self.robot_block = self.n_anchors + (3 if version >= 1 else 2)
        xmin, xmax, ymin, ymax = st.bounds
        w_top = self.fastest_winch_mps
        if fidelity == "kinematic":
            v_max = self.k * w_top
        else:  # tethers only pull, each at most F_max, and walls never add energy
            v_max = max(self.k * w_top,
                        self.k * st.winch_force_limit_N * self.horizon_steps * self.dt_s / st.cargo.mass_kg)
        self.v_max_mps = v_max
        diagonal = math.hypot(xmax - xmin, ymax - ymin)
        self.robustness_limit_m = max(diagonal, (v_max + st.rest_speed_mps) * st.drift_time_s)
        robot_low = np.zeros(self.robot_block)
        robot_high = np.concatenate([np.ones(self.n_anchors), [1.0, diagonal], [1.0] if version >= 1 else []])
        self.obs_low = np.concatenate([[xmin, ymin, -v_max, -v_max], np.tile(robot_low, self.n_robots),
                                       np.zeros(self.n_anchors), [0.0]]).astype(np.float32)
        self.obs_high = np.concatenate([[xmax, ymax, v_max, v_max], np.tile(robot_high, self.n_robots),
                                        np.ones(self.n_anchors), [1.0]]).astype(np.float32)
        self._los0 = 4 + self.n_robots * self.robot_block
        self._drift_time = st.drift_time_s  # the task's bodies: see Station.task_positions
        self._goal = st.goal_box
        self._rest2 = st.rest_speed_mps ** 2
        self.world: TetherWorld = None  # type: ignore[assignment]  # set by reset(); no step before it
        self.sight = SightCache(st)
        self._agent_index: dict[int, np.ndarray] = {}
        self._buf = np.zeros(self.obs_size, dtype=np.float32)
        self._buf_changes, self._buf_sight = -1, -1
        self._buf_tethers: list[tuple[int, Any]] = []  # (observation index, the world's tether)
        self._bounds4 = (self.obs_low[:4].astype(float).tolist(), self.obs_high[:4].astype(float).tolist())
        self._obs_at: tuple[TetherWorld, int] | None = None
        self.step_count = 0
        self.schedule = FaultSchedule([], (1.0,) * self.n_robots)
        self._reset_counters()

    def _check_rates(self) -> None:
        """The station's substep checks (:func:`~impact_env.tether.station._check_rates`) for the winches this
        environment really has: the slowest sets the tension law's gain, the fastest how far a substep moves."""
        st = self.station
        dt = st.control_period_s / st.substeps
        gain = dt * st.winch_force_limit_N / (st.cargo.mass_kg * self.slowest_winch_mps)
        if gain > 1.0:
            raise EnvConfigError(f"winches at {self.slowest_winch_mps:g} m/s are too slow for station {st.name!r}'s "
                                 f"{st.substeps} substeps: a substep would change the cargo's speed by {gain:.3g} of "
                                 "its shortfall under the force fidelity's tension law (must be <= 1)")
        step = self.k * self.fastest_winch_mps * dt
        if step > 0.25 * st.cargo.radius_m:
            raise EnvConfigError(f"winches at {self.fastest_winch_mps:g} m/s are too fast for station {st.name!r}'s "
                                 f"{st.substeps} substeps: k of them move the cargo {step:.3g} m per substep, more "
                                 "than a quarter of its radius")

    def _reset_counters(self) -> None:
        self.robustness = 0.0
        self.switches = 0
        self.snags = 0
        self.path_length_m = 0.0
        self.events: list[dict] = []  # every tether event of the episode
        self._prev_estimate = 0.0
        self._los = np.zeros(self.n_anchors, dtype=bool)
        self._state: list[tuple[float, ...]] = []
        self.time_to_goal_s: float | None = None
        self.time_in_goal_s = 0.0
        self.time_at_rest_in_goal_s = 0.0
        self._pending_faults: list[tuple[float, str, float]] = []
        self._armed_anchor_failures = 0  # anchor failures waiting for the next attachment
        self.failed_anchors: set[int] = set()  # the anchors that have shown their failure (an event)
        self.dropped_robots: set[int] = set()

    @property
    def obs_size(self) -> int:
        return 4 + self.n_robots * self.robot_block + self.n_anchors + 1

    @property
    def time_s(self) -> float:
        return self.step_count * self.dt_s

    # ------------------------------------------------------------------------------------------ episode
    def _start_in_overlap(self, rng: np.random.Generator, start: tuple[float, float]) -> tuple[float, float]:
        """A start uniform in the noise disc and the cargo's free space, by rejection in the bounds of their
        overlap: what the disc sampling above gives, for a disc so large that it rarely lands in the station.
        The overlap holds the start, so this finds a point; the start itself is the last resort."""
        import shapely

        r = self.initial_position_noise_m
        overlap = self.station.free_space().intersection(shapely.Point(start).buffer(r))
        x0, y0, x1, y1 = overlap.bounds if not overlap.is_empty else (start[0], start[1], start[0], start[1])
        for _ in range(400):
            points = np.column_stack([rng.uniform(x0, x1, 256), rng.uniform(y0, y1, 256)])
            ok = (np.hypot(points[:, 0] - start[0], points[:, 1] - start[1]) <= r) \
                & self.station.cargo_inside_many(points)
            if ok.any():
                x, y = points[int(np.argmax(ok))]
                return (float(x), float(y))
        return start

    def reset(self, rng: np.random.Generator) -> None:
        """Start a new episode: a fresh pymunk world, an empty trace, the faults drawn; randomness only from
        ``rng`` (the start position first, then the faults)."""
        st = self.station
        start = st.cargo.start_m
        if self.initial_position_noise_m > 0:
            for _ in range(1000):
                r = self.initial_position_noise_m * math.sqrt(rng.uniform())
                a = rng.uniform(0.0, 2.0 * math.pi)
                candidate = (start[0] + r * math.cos(a), start[1] + r * math.sin(a))
                if st.cargo_inside(candidate):
                    start = candidate
                    break
            else:  # a disc much larger than the station: sample where the disc and the station overlap
                start = self._start_in_overlap(rng, start)
        self.schedule = FaultSchedule.draw(self.faults, self.n_robots, rng)
        speeds = None
        if self.schedule.winch_factors != (1.0,) * self.n_robots:
            speeds = [self.pull_speed_mps * f for f in self.schedule.winch_factors]
        if self.world is None:
            self.world = TetherWorld(st, self.fidelity, pull_speed_mps=self.pull_speed_mps, start_m=start,
                                     winch_speeds_mps=speeds)
        else:  # the same as a fresh world, bit for bit (TetherWorld.restart), at a fraction of the cost
            self.world.restart(start, speeds)
        self.step_count = 0
        self._reset_counters()
        self._pending_faults = list(self.schedule.events)
        self.monitor.reset()
        x, y, vx, vy = self.world.state()
        self._read(x, y, vx, vy, jump=True)
        self._obs_at = None
        self.robustness = self._clip(self.monitor.update(st.task_positions(x, y, vx, vy)))
        self._track_goal(x, y, vx, vy, 0.0)

    def _read(self, x: float, y: float, vx: float, vy: float, jump: bool = False) -> None:
        self._state = [(x, y, vx, vy, 0.0, 0.0)]  # one body, the layout of the impact world's state
        self._los = self.sight.restart(x, y) if jump else self.sight.mask(x, y)

    def _clip(self, rho: float) -> float:
        limit = self.robustness_limit_m
        return -limit if rho < -limit else (limit if rho > limit else rho)

    def _track_goal(self, x: float, y: float, vx: float, vy: float, dt: float) -> None:
        x0, x1, y0, y1 = self._goal
        if x0 <= x <= x1 and y0 <= y <= y1:
            if self.time_to_goal_s is None:
                self.time_to_goal_s = self.time_s
            self.time_in_goal_s += dt
            self.time_at_rest_in_goal_s = self.time_at_rest_in_goal_s + dt if vx * vx + vy * vy < self._rest2 else 0.0
        else:
            self.time_in_goal_s = self.time_at_rest_in_goal_s = 0.0

    def decode(self, action: Any) -> list[int]:
        """The per-robot commands of an action: ``n_robots`` integers in ``0 .. n_commands - 1``."""
        n, top = self.n_robots, self.n_commands - 1
        if isinstance(action, np.ndarray) and type(action) is not np.ndarray:  # masked arrays, np.matrix
            if np.ma.is_masked(action):  # a masked entry is no command (tolist() would make it None)
                raise ActionError(f"action is a masked array with {int(np.ma.count_masked(action))} masked entries; "
                                  f"pass {n} integer commands ({self._commands_text()}), e.g. action.filled(0)")
            action = np.asarray(np.ma.getdata(action))
        if isinstance(action, np.ndarray) and action.dtype.kind in "iu" and action.shape == (n,):
            if n and (action.min() < 0 or action.max() > top):
                bad = int(np.flatnonzero((action < 0) | (action > top))[0])
                raise ActionError(f"action[{bad}] must be an integer in 0..{top} ({self._commands_text()}), got "
                                  f"{action[bad]!r}")
            return action.tolist()
        values = action.tolist() if isinstance(action, np.ndarray) else action
        if not isinstance(values, (list, tuple)):
            values = [values]
        if len(values) != n:
            raise ActionError(f"action must have {n} commands (one per robot: {self._commands_text()}), got "
                              f"{_brief(action)}")
        out = []
        for i, v in enumerate(values):
            if type(v) is int and 0 <= v <= top:
                out.append(v)
                continue
            try:
                f = float(v)
            except (TypeError, ValueError, OverflowError):
                raise ActionError(f"action[{i}] must be an integer in 0..{top}, got {_brief(v)}") from None
            if not math.isfinite(f) or f != int(f) or not 0 <= f <= top:
                raise ActionError(f"action[{i}] must be an integer in 0..{top} ({self._commands_text()}), got "
                                  f"{_brief(v)}")
            out.append(int(f))
        return out

    def _commands_text(self) -> str:
        hold = f", {self.hold_command} hold" if self.hold_command is not None else ""
        return f"0 keep, 1 release, 2 + j attach to anchor j of {self.n_anchors}{hold}"

    def _command(self, robot: int, command: int, rejected: list[dict]) -> None:
        world = self.world
        if command == KEEP:
            return
        if command == RELEASE:
            world.release(robot)
            return
        if command == self.hold_command:
            if not world.hold(robot):
                rejected.append({"robot": robot, "command": command, "reason": f"robot {robot} holds no tether"})
            return
        anchor = command - ATTACH0
        held = world.tether_anchor(robot)
        if held == anchor:
            world.reel(robot)  # a keep, or the end of a hold
            return
        reason = None
        holders = [r for r in range(self.n_robots) if r != robot and world.tether_anchor(r) is not None]
        owner = next((r for r in holders if world.tether_anchor(r) == anchor), None)
        x, y = self._state[0][:2]
        ax, ay = self.station.anchors[anchor].position_m
        if robot in world.dropped_robots:
            reason = f"robot {robot} has dropped out"
        elif owner is not None:
            reason = f"anchor {anchor} is held by robot {owner}"
        elif len(holders) >= self.k:
            reason = f"{self.k} other robots already hold anchors (k = {self.k})"
        elif not self._los[anchor]:
            reason = f"anchor {anchor} is not in line of sight of the cargo"
        elif math.hypot(ax - x, ay - y) <= self.station.stop_radius_m:
            reason = f"the cargo is inside anchor {anchor}'s stop radius"
        if reason is not None:
            rejected.append({"robot": robot, "command": command, "reason": reason})
            return
        if held is not None:
            world.release(robot)
        if self._armed_anchor_failures and anchor not in world.failed_anchors:
            self._armed_anchor_failures -= 1
            world.failed_anchors.add(anchor)  # it will refuse this attachment when the tether would start
        world.attach(robot, anchor, self.station.switch_time_s)
        self.switches += 1

    def _apply_faults(self) -> None:
        """The faults whose time has come (see :mod:`impact_env.tether.faults`): applied at the step's start."""
        world, now = self.world, self.time_s
        waiting = []
        for fault in self._pending_faults:
            t, kind, pick = fault
            if t > now + 1e-9:
                waiting.append(fault)
                continue
            pulling = [r for r in range(self.n_robots) if world.is_pulling(r)]
            if kind == "anchor":
                if pulling:
                    # a pulling robot holds a tether, so it has an anchor
                    world.fail_anchor(cast(int, world.tether_anchor(pulling[int(pick * len(pulling))])))
                else:
                    self._armed_anchor_failures += 1
            elif kind == "snap":
                if pulling:
                    world.snap(pulling[int(pick * len(pulling))])
                else:
                    waiting.append((now + self.dt_s, kind, pick))  # no tether to snap yet: the next step's
            else:
                present = [r for r in range(self.n_robots) if r not in world.dropped_robots]
                busy = [r for r in present if world.tether_anchor(r) is not None] or present
                world.drop_out(busy[int(pick * len(busy))])
        self._pending_faults = waiting

    def step(self, action: Any) -> tuple[float, bool, dict[str, Any]]:
        """Apply one command per robot and simulate one control period; returns (reward, terminated, info)."""
        world = self.world
        if world is None or self.step_count >= self.horizon_steps:
            check_can_step(self)
        commands = self.decode(action)
        rejected: list[dict] = []
        for robot, command in enumerate(commands):
            if command:
                self._command(robot, command, rejected)
        if self._pending_faults and self._pending_faults[0][0] <= self.time_s + 1e-9:
            self._apply_faults()
        work0 = world.winch_work_J
        x0, y0 = self._state[0][0], self._state[0][1]
        events = world.step()  # with the events of the commands above
        self.step_count += 1
        x1, y1, vx, vy = world.state()
        self._state = [(x1, y1, vx, vy, 0.0, 0.0)]  # one body, the layout of the impact world's state
        self._los = self.sight.mask(x1, y1)
        self.path_length_m += math.hypot(x1 - x0, y1 - y0)
        self._track_goal(x1, y1, vx, vy, self.dt_s)
        if events:
            step_events = [e.to_dict() for e in events]
            self.events.extend(step_events)
            for e in events:
                if e.kind == "snagged":
                    self.snags += 1
                elif e.kind in ("anchor_failed", "refused"):
                    self.failed_anchors.add(e.anchor)
                elif e.kind == "dropped_out":
                    self.dropped_robots.add(e.robot)
        else:
            step_events = []
        work = world.winch_work_J - work0
        t = self._drift_time
        if self._pair_monitor:
            estimate = self.monitor.update_pair(CARGO, x1, y1, vx * t, vy * t)  # type: ignore[union-attr]  # a HoldMonitor
        else:
            estimate = self.monitor.update({CARGO: (x1, y1), DRIFT: (vx * t, vy * t)})
        limit = self.robustness_limit_m
        if not -limit <= estimate <= limit:
            estimate = self._clip(estimate)
        self.robustness = estimate
        terminated = self.step_count >= self.horizon_steps
        if self.reward_mode == "dense":
            reward = estimate - self._prev_estimate
            self._prev_estimate = estimate
        else:
            reward = estimate if terminated else 0.0
        if work:
            reward -= self.energy_penalty * work
        return float(reward), terminated, self.info(step_events, rejected)

    def reset_info(self) -> dict[str, Any]:
        """``info`` of ``reset()``: the robustness of the start, no events yet."""
        return self.info()

    def info(self, events: list[dict] | None = None, rejected: list[dict] | None = None) -> dict[str, Any]:
        world = self.world
        vx, vy = self._state[0][2:4] if self._state else (0.0, 0.0)
        return {
            "robustness": self.robustness, "is_success": self.robustness > 0.0, "time_s": self.time_s,
            "switches": self.switches, "snags": self.snags, "path_length_m": self.path_length_m,
            "winch_work_J": world.winch_work_J if world is not None else 0.0,
            "wall_contacts": world.wall_contacts if world is not None else 0,
            "speed_mps": math.hypot(vx, vy), "time_to_goal_s": self.time_to_goal_s,
            "time_in_goal_s": self.time_in_goal_s, "time_at_rest_in_goal_s": self.time_at_rest_in_goal_s,
            "failed_anchors": sorted(self.failed_anchors) if self.failed_anchors else [],
            "dropped_robots": sorted(self.dropped_robots) if self.dropped_robots else [],
            "events": events or [], "rejected": rejected or [],
        }

    # ------------------------------------------------------------------------------------- observation
    def observation(self) -> np.ndarray:
        """Central observation (see TetherEnv's docstring for the layout)."""
        return self._central().copy()

    def agent_observation(self, robot: int) -> np.ndarray:
        """A robot's observation: the same layout with its own block first, then the others in order."""
        index = self._agent_index.get(robot)
        if index is None:
            order = [robot] + [i for i in range(self.n_robots) if i != robot]
            blocks = np.arange(4, self._los0).reshape(self.n_robots, self.robot_block)[order].reshape(-1)
            index = self._agent_index[robot] = np.concatenate([np.arange(4), blocks,
                                                               np.arange(self._los0, self.obs_size)])
        return self._central()[index]

    def _central(self) -> np.ndarray:
        """The central observation of this step, kept up to date in one buffer: the robot blocks are rewritten
        when a tether changed, the mask when the line of sight may have, the rest every step (the same values as
        building it from zeros)."""
        world, sight = self.world, self.sight
        now = (world, self.step_count)
        if self._obs_at == now:
            return self._buf
        buf, n = self._buf, self.n_anchors
        if self._obs_at is None or self._obs_at[0] is not world or self._buf_changes != world.changes:
            block, flag = self.robot_block, self.hold_command is not None
            buf[4: self._los0] = 0.0
            self._buf_tethers = []
            for robot, t in enumerate(world._tethers):
                if t is not None:
                    base = 4 + robot * block
                    buf[base + t.anchor] = 1.0
                    if flag and t.held:
                        buf[base + n + 2] = 1.0
                    self._buf_tethers.append((base + n, t))
            self._buf_changes = world.changes
        x, y, vx, vy = self._state[0][:4]
        buf[0], buf[1], buf[2], buf[3] = x, y, vx, vy
        t_switch, clock = self.station.switch_time_s, world.time_s
        for at, t in self._buf_tethers:
            buf[at] = max(0.0, t.ready_s - clock) / t_switch if not t.pulling and t_switch > 0 else 0.0
            buf[at + 1] = math.hypot(t.ax - x, t.ay - y)
        if self._buf_sight != sight.version:
            buf[self._los0: self._los0 + n] = self._los
            self._buf_sight = sight.version
        buf[-1] = time_left(self)
        low, high = self._bounds4
        if not (low[0] <= x <= high[0] and low[1] <= y <= high[1] and low[2] <= vx <= high[2]
                and low[3] <= vy <= high[3]):
            clip_to_space(buf, self)  # the one bound a state could leave (the others hold by construction)
        self._obs_at = now
        return buf

    def line_of_sight_mask(self) -> np.ndarray:
        """Which anchors a tether from the cargo reaches now (bool, n_anchors)."""
        return self._los.copy()


def _brief(value: Any) -> str:
    from impact_env.errors import brief

    return brief(value)
