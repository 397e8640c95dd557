"""The episode logic shared by the tether Gymnasium and PettingZoo environments.

One :class:`TetherCore` owns a station, the pymunk :class:`~impact_env.tether.physics.TetherWorld` (rebuilt on
every reset), the online STL monitor and the fleet's rules. The environment classes only translate its inputs
and outputs into their APIs.

Commands, per robot and step, processed in robot order: ``0`` keep, ``1`` release (at once), ``2 + j`` attach to
anchor ``j`` (the tether pulls ``t_switch`` later; a robot holding another anchor lets go of it first). An attach
is REJECTED, the robot keeping what it had and ``info["rejected"]`` saying why, when the anchor is not in line of
sight of the cargo centre, the cargo is already inside the anchor's stop radius, another robot holds the anchor,
or ``k`` other robots already hold anchors (pulling or attaching). Attaching to the anchor a robot already holds
is a keep. A command that is not an integer in ``0 .. n_anchors + 1`` (or NaN, or the wrong number of commands)
raises :class:`~impact_env.errors.ActionError`: no rule can make sense of it. The rewards: see :class:`TetherCore`.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from impact_env.env_shell import check_can_step, clip_to_space, time_left
from impact_env.errors import ActionError, EnvConfigError, ImpactEnvError
from impact_env.stl import OnlineMonitor
from impact_env.tether.physics import FIDELITIES, TetherWorld
from impact_env.tether.station import CARGO, Station, load_station

REWARD_MODES = ("dense", "sparse")
KEEP, RELEASE, ATTACH0 = 0, 1, 2


class TetherCore:
    """Station + tether physics + STL monitor + fleet rules: reset, apply commands, observe.

    Reward: ``"dense"`` (default) the per-step increment of the online robustness estimate of the station's task
    (the trace so far with its last sample held), so an episode's rewards sum to its final robustness;
    ``"sparse"`` the final robustness on the last step. Both subtract ``energy_penalty`` times the step's winch
    work (J).

    Args:
        station: a Station, a shipped station name or a path to a TOML file.
        fidelity: ``"kinematic"`` (default), ``"reel"`` or ``"force"`` (see :mod:`impact_env.tether.physics`).
        reward_mode: ``"dense"`` or ``"sparse"``.
        energy_penalty: reward cost per joule of winch work (>= 0).
        pull_speed_mps: the winches' actual ``w`` (default the station's): a mismatch for a planner.
        max_active: ``k`` for this environment (default the station's), 1 .. number of robots.
        initial_position_noise_m: the cargo starts uniformly within this radius of its start (disc kept inside).
    """

    def __init__(self, station: Station | str, fidelity: str = "kinematic", reward_mode: str = "dense",
                 energy_penalty: float = 0.0, pull_speed_mps: float | None = None, max_active: int | None = None,
                 initial_position_noise_m: float = 0.0) -> None:
        self.station = station if isinstance(station, Station) else load_station(station)
        st = self.station
        if fidelity not in FIDELITIES:
            raise EnvConfigError(f"fidelity must be one of {FIDELITIES}, got {fidelity!r}")
        if reward_mode not in REWARD_MODES:
            raise EnvConfigError(f"reward_mode must be one of {REWARD_MODES}, got {reward_mode!r}")
        for name, value in (("energy_penalty", energy_penalty), ("initial_position_noise_m", initial_position_noise_m)):
            if isinstance(value, bool) or not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise EnvConfigError(f"{name} must be a finite number >= 0, got {value!r}")
        if pull_speed_mps is not None and (isinstance(pull_speed_mps, bool) or not (
                isinstance(pull_speed_mps, (int, float)) and math.isfinite(pull_speed_mps) and pull_speed_mps > 0)):
            raise EnvConfigError(f"pull_speed_mps must be a finite number > 0 or None, got {pull_speed_mps!r}")
        if max_active is not None and (isinstance(max_active, bool) or not isinstance(max_active, int)
                                       or not 1 <= max_active <= st.n_robots):
            raise EnvConfigError(f"max_active must be an integer in 1..{st.n_robots} (the station's robots) or None, "
                                 f"got {max_active!r}")
        self.fidelity = fidelity
        self.reward_mode = reward_mode
        self.energy_penalty = float(energy_penalty)
        self.pull_speed_mps = st.pull_speed_mps if pull_speed_mps is None else float(pull_speed_mps)
        self.k = st.k if max_active is None else max_active
        self.initial_position_noise_m = float(initial_position_noise_m)

        self.n_robots = st.n_robots
        self.n_anchors = st.n_anchors
        self.n_commands = self.n_anchors + 2
        self.dt_s = st.control_period_s
        self.monitor = OnlineMonitor(st.formula, st.region_map(), self.dt_s)
        self.horizon_steps = self.monitor.horizon_steps
        self.robot_block = self.n_anchors + 2  # anchor one-hot, attach time left (fraction), tether length
        xmin, xmax, ymin, ymax = st.bounds
        if fidelity == "kinematic":
            v_max = self.k * self.pull_speed_mps
        else:  # tethers only pull, each at most F_max, and walls never add energy
            v_max = max(self.k * self.pull_speed_mps,
                        self.k * st.winch_force_limit_N * self.horizon_steps * self.dt_s / st.cargo.mass_kg)
        self.v_max_mps = v_max
        diagonal = math.hypot(xmax - xmin, ymax - ymin)
        robot_low = np.zeros(self.robot_block)
        robot_high = np.concatenate([np.ones(self.n_anchors), [1.0, diagonal]])
        self.obs_low = np.concatenate([[xmin, ymin, -v_max, -v_max], np.tile(robot_low, self.n_robots),
                                       np.zeros(self.n_anchors), [0.0]]).astype(np.float32)
        self.obs_high = np.concatenate([[xmax, ymax, v_max, v_max], np.tile(robot_high, self.n_robots),
                                        np.ones(self.n_anchors), [1.0]]).astype(np.float32)
        self.world: TetherWorld = None  # type: ignore[assignment]  # set by reset(); no step before it
        self.step_count = 0
        self._reset_counters()

    def _reset_counters(self) -> None:
        self.robustness = 0.0
        self.switches = 0
        self.snags = 0
        self.path_length_m = 0.0
        self.events: list[dict] = []  # every tether event of the episode
        self._prev_estimate = 0.0
        self._los = np.zeros(self.n_anchors, dtype=bool)
        self._state: list[tuple[float, ...]] = []

    @property
    def obs_size(self) -> int:
        return 4 + self.n_robots * self.robot_block + self.n_anchors + 1

    @property
    def time_s(self) -> float:
        return self.step_count * self.dt_s

    # ------------------------------------------------------------------------------------------ episode
    def reset(self, rng: np.random.Generator) -> None:
        """Start a new episode: a fresh pymunk world, an empty trace; randomness only from ``rng``."""
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
            else:  # pragma: no cover - the start itself is inside, so a sample lands inside almost surely
                raise ImpactEnvError("could not place the cargo inside the station near its start")
        self.world = TetherWorld(st, self.fidelity, pull_speed_mps=self.pull_speed_mps, start_m=start)
        self.step_count = 0
        self._reset_counters()
        self.monitor.reset()
        self._read()
        self.robustness = self.monitor.update({CARGO: self.world.position_m})

    def _read(self) -> None:
        x, y = self.world.position_m
        vx, vy = self.world.velocity_mps
        self._state = [(x, y, vx, vy, 0.0, 0.0)]  # one body, the layout of the impact world's state
        self._los = self.station.line_of_sight((x, y))

    def decode(self, action: Any) -> list[int]:
        """The per-robot commands of an action: ``n_robots`` integers in ``0 .. n_anchors + 1``."""
        values = action.tolist() if isinstance(action, np.ndarray) else action
        if not isinstance(values, (list, tuple)):
            values = [values]
        n, top = self.n_robots, self.n_commands - 1
        if len(values) != n:
            raise ActionError(f"action must have {n} commands (one per robot: 0 keep, 1 release, 2 + j attach to "
                              f"anchor j), got {action!r}")
        out = []
        for i, v in enumerate(values):
            try:
                f = float(v)
            except (TypeError, ValueError):
                raise ActionError(f"action[{i}] must be an integer in 0..{top}, got {v!r}") from None
            if not math.isfinite(f) or f != int(f) or not 0 <= f <= top:
                raise ActionError(f"action[{i}] must be an integer in 0..{top} (0 keep, 1 release, 2 + j attach to "
                                  f"anchor j of {self.n_anchors}), got {v!r}")
            out.append(int(f))
        return out

    def _command(self, robot: int, command: int, rejected: list[dict]) -> None:
        world = self.world
        if command == KEEP:
            return
        if command == RELEASE:
            world.release(robot)
            return
        anchor = command - ATTACH0
        held = world.tether_anchor(robot)
        if held == anchor:
            return
        reason = None
        holders = [r for r in range(self.n_robots) if r != robot and world.tether_anchor(r) is not None]
        owner = next((r for r in holders if world.tether_anchor(r) == anchor), None)
        x, y = world.position_m
        ax, ay = self.station.anchors[anchor].position_m
        if owner is not None:
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
        world.attach(robot, anchor, self.station.switch_time_s)
        self.switches += 1

    def step(self, action: Any) -> tuple[float, bool, dict[str, Any]]:
        """Apply one command per robot and simulate one control period; returns (reward, terminated, info)."""
        check_can_step(self)
        commands = self.decode(action)
        world = self.world
        rejected: list[dict] = []
        for robot, command in enumerate(commands):
            self._command(robot, command, rejected)
        work0 = world.winch_work_J
        x0, y0 = world.position_m
        events = world.step()  # with the events of the commands above
        self.step_count += 1
        self._read()
        x1, y1 = world.position_m
        self.path_length_m += math.hypot(x1 - x0, y1 - y0)
        step_events = [e.to_dict() for e in events]
        self.events.extend(step_events)
        self.snags += sum(e.kind == "snagged" for e in events)
        work = world.winch_work_J - work0
        estimate = self.monitor.update({CARGO: (x1, y1)})
        self.robustness = estimate
        terminated = self.step_count >= self.horizon_steps
        if self.reward_mode == "dense":
            reward = estimate - self._prev_estimate
            self._prev_estimate = estimate
        else:
            reward = estimate if terminated else 0.0
        reward -= self.energy_penalty * work
        return float(reward), terminated, self.info(step_events, rejected)

    def reset_info(self) -> dict[str, Any]:
        """``info`` of ``reset()``: the robustness of the start, no events yet."""
        return self.info()

    def info(self, events: list[dict] | None = None, rejected: list[dict] | None = None) -> dict[str, Any]:
        world = self.world
        return {
            "robustness": self.robustness, "is_success": self.robustness > 0.0, "time_s": self.time_s,
            "switches": self.switches, "snags": self.snags, "path_length_m": self.path_length_m,
            "winch_work_J": world.winch_work_J if world is not None else 0.0,
            "wall_contacts": world.wall_contacts if world is not None else 0,
            "events": list(events or []), "rejected": list(rejected or []),
        }

    # ------------------------------------------------------------------------------------- observation
    def observation(self) -> np.ndarray:
        """Central observation (see TetherEnv's docstring for the layout)."""
        return self._observe(range(self.n_robots))

    def agent_observation(self, robot: int) -> np.ndarray:
        """A robot's observation: the same layout with its own block first, then the others in order."""
        return self._observe([robot] + [i for i in range(self.n_robots) if i != robot])

    def _observe(self, order) -> np.ndarray:
        world, st = self.world, self.station
        x, y, vx, vy = self._state[0][:4]
        out = np.zeros(self.obs_size, dtype=np.float64)
        out[:4] = (x, y, vx, vy)
        t_switch = st.switch_time_s
        for slot, robot in enumerate(order):
            base = 4 + slot * self.robot_block
            anchor = world.tether_anchor(robot)
            if anchor is not None:
                out[base + anchor] = 1.0
                out[base + self.n_anchors] = world.attach_remaining_s(robot) / t_switch if t_switch > 0 else 0.0
                out[base + self.n_anchors + 1] = world.tether_length_m(robot)
        los0 = 4 + self.n_robots * self.robot_block
        out[los0: los0 + self.n_anchors] = self._los
        out[-1] = time_left(self)
        return clip_to_space(out.astype(np.float32), self)

    def line_of_sight_mask(self) -> np.ndarray:
        """Which anchors a tether from the cargo reaches now (bool, n_anchors)."""
        return self._los.copy()
