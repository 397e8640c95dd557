"""The episode logic of the transport environments: scenario, physics, STL monitor, bookkeeping.

One :class:`TransportCore` owns a scenario, the pymunk :class:`~impact_env.transport.physics.World` (rebuilt on
every reset), the online STL monitor and the episode bookkeeping (fuel, impacts). The Gymnasium and PettingZoo
classes (:mod:`impact_env.transport.gym_env`, :mod:`impact_env.transport.pettingzoo_env`) only translate its
inputs and outputs into their APIs; the rewards are defined in :class:`TransportCore`'s docstring.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from impact_env.env_shell import check_can_step, clip_to_space, time_left
from impact_env.errors import ActionError, EnvConfigError
from impact_env.stl import OnlineMonitor, conjuncts
from impact_env.stl.compiled import CompiledMonitor, compiled_monitor
from impact_env.transport import native, starts
from impact_env.transport.actions import is_masked, numbers_of
from impact_env.transport.physics import ImpactEvent, World
from impact_env.transport.scenario import Scenario, load_scenario

REWARD_MODES = ("dense", "sparse", "conjuncts")
OBS_PER_BODY = 7  # x, y, vx, vy, cos(heading), sin(heading), angular velocity
ACTION_PER_ROBOT = 3  # body-frame Fx, Fy, torque, each in [-1, 1]
_FLOAT32_LIMIT = float(np.finfo(np.float32).max) / 2  # observation bounds stay finite in float32
MAX_THRUST_NOISE = 10.0  # std of the multiplicative noise; beyond, 0 * (1 + noise * z) overflows to NaN
MAX_FUEL_PENALTY = 1e6  # reward per N s; beyond, a step's penalty can overflow to -inf
MAX_IMPACT_NOISE_MPS = 1.0  # post-impact velocity error (m/s per axis); beyond, it dwarfs the planned speeds


def speed_bounds(scenario: Scenario, duration_s: float) -> tuple[float, float]:
    """Speeds no body can exceed within ``duration_s`` (m/s, rad/s): finite observation bounds.

    Contacts with e <= 1 never add kinetic energy E, and thrust adds at most
    dE/dt <= sum_i |F_i| |v_i| <= sum_i |F_i| sqrt(2 E / m_i), so sqrt(E) grows at most linearly:
    sqrt(E(t)) <= sqrt(E(0)) + t * sum_i |F_i| / sqrt(2 m_i). Every speed is then <= sqrt(2 E / m).
    Frictionless contacts through the centres create no spin, so only torque changes yaw rates.
    """
    bodies = scenario.bodies
    e0 = sum(0.5 * b.mass_kg * (b.velocity_mps[0] ** 2 + b.velocity_mps[1] ** 2)
             + 0.5 * b.inertia_kgm2 * b.angular_velocity_radps ** 2 for b in bodies)
    growth = sum(math.hypot(*r.wrench_limits[:2]) / math.sqrt(2.0 * r.mass_kg) for r in scenario.robots)
    energy = (math.sqrt(e0) + duration_s * growth) ** 2
    v_max = math.sqrt(2.0 * energy / min(b.mass_kg for b in bodies))
    w_max = max(abs(b.angular_velocity_radps)
                + (duration_s * b.wrench_limits[2] / b.inertia_kgm2 if b.is_robot else 0.0) for b in bodies)
    return min(v_max, _FLOAT32_LIMIT), min(max(w_max, 1.0), _FLOAT32_LIMIT)


def robustness_limit(scenario: Scenario) -> float:
    """Diagonal (m) of the box around the world and every region: no signed distance in the task exceeds it."""
    xs = [scenario.world_box[0], scenario.world_box[1]]
    ys = [scenario.world_box[2], scenario.world_box[3]]
    for region in scenario.regions + scenario.obstacles:
        xmin, xmax, ymin, ymax = region.polygon.bounds
        xs += (xmin, xmax)
        ys += (ymin, ymax)
    return math.hypot(max(xs) - min(xs), max(ys) - min(ys))


@dataclass
class EpisodeLog:
    """What an episode produced so far: summary numbers for the CLI, the benchmark and ``info``."""

    fuel_Ns: float = 0.0
    impacts: list[ImpactEvent] = field(default_factory=list)
    robustness: float = 0.0


class TransportCore:
    """Scenario + physics + STL monitor: reset, apply an action, observe.

    Reward (both environments):

    - ``"dense"``: the per-step increment of the online robustness estimate, ``r_k = rho_k - rho_(k-1)`` with
      ``rho_0 = 0`` before the first step. The estimate ``rho_k`` is the robustness of the trace so far with its
      last sample held to the horizon, so at the last step it is the trace's exact robustness. The rewards of
      an episode therefore sum to its final robustness: this is potential-based shaping, which never changes
      which behaviour is optimal (undiscounted).
    - ``"sparse"``: 0 on every step but the last, which gives the final robustness.
    - ``"conjuncts"``: the per-step increment of the MEAN of the online estimates of the task's conjuncts
      (:func:`impact_env.stl.conjuncts`: nested And flattened, G distributed over And), so the rewards sum to
      that mean at the end. The task's robustness is their MIN, and a min only moves with its smallest part: in
      the corridor the wall-clearance conjuncts (about 1 m) sit far above "F in(O1, goal)" (-5.25 m) until the
      object nears the goal, so under ``"dense"`` a robot that grazes a wall early is charged only when the
      object arrives, tens of seconds later. Here every conjunct is credited when it changes. This is shaping
      that changes the objective (a mean is not a min): ``info["robustness"]`` and ``is_success`` stay the task's.
    - all: minus ``fuel_penalty`` times the step's fuel, sum over robots of |F| * control period (N s).

    A task that holds or fails whatever the bodies do (``F[0,20] true``, or ``true | in(O1, goal)``) has the
    robustness +-inf. No signed distance between a point of the world and a region can exceed the diagonal of
    the box around the world and every region, so the core reports robustness clipped to +- that length
    (:attr:`robustness_limit_m`): rewards and ``info["robustness"]`` stay finite, the rewards still sum to the
    (clipped) final robustness, and the sign, hence ``is_success``, is unchanged.

    Speed: the substeps, the action's scaling and the observation run in C (:mod:`impact_env.transport.native`)
    and the STL monitor too for the shipped formula classes (:mod:`impact_env.stl.compiled`), on buffers made
    once: the state (:attr:`state`, (n_bodies, 6) float64), the wrenches and the observation. Every number is the
    pure-Python path's, bit for bit; ``info`` is a new plain dict per step.

    Args:
        scenario: a Scenario, a shipped scenario name or a path to a TOML file.
        reward_mode: ``"dense"`` (default), ``"sparse"`` or ``"conjuncts"``; see above.
        fuel_penalty: reward cost per N s of fuel (>= 0).
        restitution: simulate with this restitution instead of the scenario's (model mismatch studies).
        thrust_noise: standard deviation of multiplicative thrust noise (0.05 = 5 %), re-clipped to limits.
        initial_position_noise_m: objects start uniformly within this radius of their scenario position.
        impact_velocity_noise_mps: after each robot-object impact the object's velocity gets a uniform error in
            [-this, this] m/s per axis (drawn from the reset seed): the error an impact-robust plan tolerates.
    """

    def __init__(self, scenario: Scenario | str, reward_mode: str = "dense", fuel_penalty: float = 0.0,
                 restitution: float | None = None, thrust_noise: float = 0.0,
                 initial_position_noise_m: float = 0.0, impact_velocity_noise_mps: float = 0.0) -> None:
        self.scenario = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
        if reward_mode not in REWARD_MODES:
            raise EnvConfigError(f"reward_mode must be one of {REWARD_MODES}, got {reward_mode!r}")
        for name, value, most in (("fuel_penalty", fuel_penalty, MAX_FUEL_PENALTY),
                                  ("thrust_noise", thrust_noise, MAX_THRUST_NOISE),
                                  ("initial_position_noise_m", initial_position_noise_m, math.inf),
                                  ("impact_velocity_noise_mps", impact_velocity_noise_mps, MAX_IMPACT_NOISE_MPS)):
            if not (isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
                    and 0 <= value <= most):
                limit = f"in [0, {most:g}]" if math.isfinite(most) else ">= 0"
                raise EnvConfigError(f"{name} must be a finite number {limit}, got {value!r}")
        if restitution is not None and not (isinstance(restitution, (int, float)) and 0.0 <= restitution <= 1.0):
            raise EnvConfigError(f"restitution must be in [0, 1] or None, got {restitution!r}")
        if initial_position_noise_m > 0:
            starts.check_noise(self.scenario, float(initial_position_noise_m))
        self.reward_mode = reward_mode
        self.fuel_penalty = float(fuel_penalty)
        self.restitution = restitution
        self.thrust_noise = float(thrust_noise)
        self.initial_position_noise_m = float(initial_position_noise_m)
        self.impact_velocity_noise_mps = float(impact_velocity_noise_mps)

        sc = self.scenario
        self.n_robots = len(sc.robots)
        self.n_bodies = len(sc.bodies)
        self.body_names = [b.name for b in sc.bodies]
        self.dt_s = sc.control_period_s
        self.monitor = self._new_monitor(sc.formula)
        self.horizon_steps = self.monitor.horizon_steps
        self.conjunct_monitors = ([self._new_monitor(part) for part in conjuncts(sc.formula)]
                                  if reward_mode == "conjuncts" else [])
        self.robustness_limit_m = robustness_limit(sc)
        n = self.n_robots * ACTION_PER_ROBOT
        self._action_shapes = ((n,), (self.n_robots, ACTION_PER_ROBOT))
        self.wrench_limits = np.array([r.wrench_limits for r in sc.robots], dtype=float)
        self._limits_py = [(float(fx), float(fy), float(tau)) for fx, fy, tau in self.wrench_limits]

        xmin, xmax, ymin, ymax = sc.world_box
        v_max, w_max = speed_bounds(sc, self.horizon_steps * self.dt_s)
        low = np.tile(np.array([xmin, ymin, -v_max, -v_max, -1.0, -1.0, -w_max], dtype=np.float32), self.n_bodies)
        high = np.tile(np.array([xmax, ymax, v_max, v_max, 1.0, 1.0, w_max], dtype=np.float32), self.n_bodies)
        self.obs_low = np.append(low, np.float32(0.0))
        self.obs_high = np.append(high, np.float32(1.0))
        self.world: World = None  # type: ignore[assignment]  # set by reset(); check_can_step refuses a step before
        self.step_count = 0
        self.log = EpisodeLog()
        self._last_wrenches: list[list[float]] = [[0.0, 0.0, 0.0] for _ in range(self.n_robots)]
        self.state = np.zeros((self.n_bodies, 6))  # per body x, y, vx, vy, heading, omega after the last step
        self._obs = np.zeros(self.obs_size, dtype=np.float32)
        self._observer = None if native.Observer is None else native.Observer(self.state, self._obs, self.obs_low,
                                                                               self.obs_high)
        # each robot's observation: its own body's block first, then the others in order, then the time left
        self._agent_orders = [np.array([OBS_PER_BODY * j + c for j in [i] + [b for b in range(self.n_bodies) if b != i]
                                        for c in range(OBS_PER_BODY)] + [OBS_PER_BODY * self.n_bodies])
                              for i in range(self.n_robots)]
        self._prev_estimate = 0.0
        self._set_action = self._set_agent_actions = None  # the world's compiled action readers

    def _new_monitor(self, formula) -> CompiledMonitor | OnlineMonitor:
        """The compiled monitor reading :attr:`state` if the formula is of its class, else OnlineMonitor."""
        sc = self.scenario
        monitor = compiled_monitor(formula, sc.region_map(), self.dt_s, self.body_names)
        return monitor if monitor is not None else OnlineMonitor(formula, sc.region_map(), self.dt_s)

    def _update(self, monitor: CompiledMonitor | OnlineMonitor) -> float:
        """Feed the monitor the positions of :attr:`state`; return its robustness estimate."""
        if type(monitor) is CompiledMonitor:
            return monitor.update_rows(self.state)
        return monitor.update(self._positions())

    @property
    def last_wrenches(self) -> list[tuple[float, float, float]]:
        """Each robot's body-frame (Fx, Fy, torque) of the last step (N, N m)."""
        return [(fx, fy, tau) for fx, fy, tau in self._last_wrenches]

    @property
    def _state(self) -> list[tuple[float, ...]]:
        """:attr:`state` as one (x, y, vx, vy, heading, omega) tuple per body; empty before the first reset."""
        return [] if self.world is None else [tuple(row) for row in self.state.tolist()]

    # ------------------------------------------------------------------------------------------ episode
    @property
    def obs_size(self) -> int:
        return self.n_bodies * OBS_PER_BODY + 1

    @property
    def time_s(self) -> float:
        return self.step_count * self.dt_s

    def reset(self, rng: np.random.Generator) -> None:
        """Start a new episode: a fresh pymunk world, an empty trace; randomness only from ``rng``."""
        overrides = {}
        if self.initial_position_noise_m > 0:
            overrides = starts.draw_starts(self.scenario, self.initial_position_noise_m, rng)
        self.world = World(self.scenario, restitution=self.restitution, initial_positions_m=overrides,
                           impact_velocity_noise_mps=self.impact_velocity_noise_mps, rng=rng)
        self._rng = rng
        loop = self.world._loop
        self._set_action = None if loop is None else loop.set_action
        self._set_agent_actions = None if loop is None else loop.set_agent_actions
        self.step_count = 0
        self.log = EpisodeLog()
        self._last_wrenches = [[0.0, 0.0, 0.0] for _ in range(self.n_robots)]
        self.monitor.reset()
        self.world.read_state_into(self.state)
        self.log.robustness = self._clip(self._update(self.monitor))
        for part in self.conjunct_monitors:
            part.reset()
            self._update(part)
        self._prev_estimate = 0.0

    def reset_info(self) -> dict[str, Any]:
        """``info`` of ``reset()``: the robustness of the first sample, nothing happened yet."""
        return {"robustness": self.log.robustness, "is_success": self.log.robustness > 0.0,
                "impacts": [], "fuel_Ns": 0.0, "time_s": 0.0}

    def _clip(self, rho: float) -> float:
        limit = self.robustness_limit_m
        return limit if rho > limit else (-limit if rho < -limit else rho)

    def _positions(self) -> dict[str, tuple[float, float]]:
        return {name: (s[0], s[1]) for name, s in zip(self.body_names, self.state.tolist())}

    def wrenches_from_action(self, action: Any) -> list[tuple[float, float, float]]:
        """Scale a normalised action (n_robots * 3 numbers in [-1, 1]) to body-frame (Fx, Fy, torque).

        The action has shape (3 n_robots,) or (n_robots, 3); any other shape, non-numbers or a ragged list
        raise :class:`ActionError` (:mod:`impact_env.transport.actions`). Values outside [-1, 1] are clipped (so
        limits are never exceeded); NaN or infinite values raise :class:`ActionError`, since no clipping can
        make sense of them.
        """
        if type(action) is np.ndarray and action.dtype.kind == "f" and action.shape == self._action_shapes[0]:
            values = action.tolist()  # the common case, kept fast
        else:
            values = numbers_of(action, self._action_shapes, "action", "Fx, Fy, torque per robot")
        if not all(map(math.isfinite, values)):
            bad = [i for i, x in enumerate(values) if not math.isfinite(x)]
            raise ActionError(f"action contains NaN or infinite values at indices {bad}; actions must be finite "
                              "numbers in [-1, 1]")
        wrenches: list[tuple[float, float, float]] = []
        for i, (fx, fy, tau) in enumerate(self._limits_py):
            x, y, t = values[3 * i: 3 * i + 3]
            wrenches.append(((1.0 if x > 1.0 else (-1.0 if x < -1.0 else x)) * fx,
                             (1.0 if y > 1.0 else (-1.0 if y < -1.0 else y)) * fy,
                             (1.0 if t > 1.0 else (-1.0 if t < -1.0 else t)) * tau))
        if self.thrust_noise > 0:
            noisy = np.array(wrenches) * (1.0 + self.thrust_noise * self._rng.standard_normal((self.n_robots, 3)))
            np.clip(noisy, -self.wrench_limits, self.wrench_limits, out=noisy)
            wrenches = [(fx, fy, tau) for fx, fy, tau in noisy.tolist()]
        return wrenches

    def _set_wrenches(self, action: Any) -> list[list[float]]:
        """Write the action's wrenches (:meth:`wrenches_from_action`) into the world's buffer; return its rows.

        The compiled loop reads float32/float64 arrays of an accepted shape and lists of one (3,) array per
        robot; anything else, and a non-finite action (for its error), takes the Python path.
        """
        if self._set_action is None or is_masked(action) or self._set_action(action) is not True:
            wrench = self.world.wrench
            wrench[...] = self.wrenches_from_action(action)
            return wrench.tolist()
        return self._with_thrust_noise(self.world.wrench)

    def _with_thrust_noise(self, wrench: np.ndarray) -> list[list[float]]:
        """The thrust noise of :meth:`wrenches_from_action` applied to ``wrench`` in place; its rows."""
        if self.thrust_noise > 0:
            noisy = wrench * (1.0 + self.thrust_noise * self._rng.standard_normal((self.n_robots, 3)))
            np.clip(noisy, -self.wrench_limits, self.wrench_limits, out=noisy)
            wrench[...] = noisy
        return wrench.tolist()

    def step(self, action: Any) -> tuple[float, bool, dict[str, Any]]:
        """Apply an action for one control period; returns (reward, terminated, info)."""
        world = self.world
        if world is None or self.step_count >= self.horizon_steps:
            check_can_step(self)
        self._last_wrenches = self._set_wrenches(action)
        return self._advance(world)

    def step_agents(self, actions: Any, agents: tuple[str, ...], joint_action: Any) -> tuple[float, bool, dict]:
        """:meth:`step` with the PettingZoo env's actions: a dict from agent (robot i is ``agents[i]``) to its
        (3,) action. The compiled loop reads a dict of float arrays; anything else takes ``joint_action(actions)``
        (the env's Python path, with its errors) and :meth:`step`."""
        world, fast = self.world, self._set_agent_actions
        if world is None or fast is None or fast(actions, agents, np.ndarray) is not True:
            return self.step(joint_action(actions))
        if self.step_count >= self.horizon_steps:
            check_can_step(self)
        self._last_wrenches = self._with_thrust_noise(world.wrench)
        return self._advance(world)

    def _advance(self, world: World) -> tuple[float, bool, dict[str, Any]]:
        """The rest of a step once the wrenches are set: physics, STL, fuel, reward, info."""
        wrenches = self._last_wrenches
        events = world.step()
        self.step_count += 1
        world.read_state_into(self.state)
        estimate = self._clip(self._update(self.monitor))
        terminated = self.step_count >= self.horizon_steps
        if terminated:
            events = events + world.flush_impacts()
        hypot = math.hypot
        fuel = self.dt_s * sum(hypot(w[0], w[1]) for w in wrenches)
        log = self.log
        log.fuel_Ns += fuel
        if events:
            log.impacts.extend(events)
        log.robustness = estimate
        if self.reward_mode == "dense":
            reward = estimate - self._prev_estimate
            self._prev_estimate = estimate
        elif self.reward_mode == "conjuncts":
            potential = sum(self._clip(self._update(part)) for part in self.conjunct_monitors) \
                / len(self.conjunct_monitors)
            reward = potential - self._prev_estimate
            self._prev_estimate = potential
        else:
            reward = estimate if terminated else 0.0
        reward -= self.fuel_penalty * fuel
        info = {
            "robustness": estimate,
            "is_success": estimate > 0.0,
            "impacts": [e.to_dict() for e in events] if events else [],
            "fuel_Ns": log.fuel_Ns,
            "time_s": self.step_count * self.dt_s,
        }
        return float(reward), terminated, info

    # ------------------------------------------------------------------------------------- observation
    def observation(self) -> np.ndarray:
        """Central observation: per body (x, y, vx, vy, cos, sin, omega), then the fraction of time left."""
        if self._observer is not None:
            return self._observer(time_left(self)).copy()
        return self._observe(range(self.n_bodies))

    def agent_observation(self, robot_index: int) -> np.ndarray:
        """A robot's observation: the same layout with its own body first, then the others in order."""
        return self.observation()[self._agent_orders[robot_index]]

    def agent_observations(self) -> list[np.ndarray]:
        """:meth:`agent_observation` of every robot, from one central observation."""
        central = self.observation()
        return [central[order] for order in self._agent_orders]

    def agent_observation_dict(self, names: tuple[str, ...]) -> dict[str, np.ndarray]:
        """``{names[i]: agent_observation(i)}``, each a row (view) of one new array."""
        if self._observer is not None:
            return self._observer.agents(time_left(self), np.empty((self.n_robots, self.obs_size), np.float32), names)
        return dict(zip(names, self.agent_observations()))

    def _observe(self, order) -> np.ndarray:
        out: list[float] = []
        state = self.state.tolist()
        for i in order:
            x, y, vx, vy, th, om = state[i]
            out += (x, y, vx, vy, math.cos(th), math.sin(th), om)
        out.append(time_left(self))
        # a disc centre can sit a hair outside the box only by float32 rounding; keep obs inside the space
        return clip_to_space(np.array(out, dtype=np.float32), self)

    def robot_forces_world(self) -> list[tuple[float, float]]:
        """Last applied force of each robot rotated into the world frame (N), for rendering."""
        out = []
        for (fx, fy, _), s in zip(self.last_wrenches, self._state):
            c, sn = math.cos(s[4]), math.sin(s[4])
            out.append((c * fx - sn * fy, sn * fx + c * fy))
        return out
