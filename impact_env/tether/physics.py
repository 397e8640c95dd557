"""The pymunk world of a station: a free-floating cargo disc pulled by tethers toward wall anchors.

Conventions of the impact world (:mod:`impact_env.transport.physics`): no gravity, ``space.damping = 1.0`` (no
damping; pymunk's damping is a retention factor), zero friction, every shape gets ``sqrt(e)`` so a cargo-wall
contact bounces with exactly the station's restitution ``e``, collision slop 0.1 mm, and a fresh space per
episode. The station's walls are static segments; the cargo is a dynamic disc; each pulling tether joins the
cargo's centre to its anchor. How a tether pulls depends on the fidelity (``"kinematic"``: the thesis's Eq. (5)
exactly; ``"reel"``: slide joints reeled in at ``w``; ``"force"``: a saturating winch tension), and the events
of a tether (attached, released, arrived, snagged, blocked) and the winch work are counted the same way in all
three: :class:`TetherWorld` describes each.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pymunk

from impact_env.errors import TetherError
from impact_env.tether.station import Station

FIDELITIES = ("kinematic", "reel", "force")
_SLOP_M = 1e-4


@dataclass(frozen=True)
class TetherEvent:
    """Something that happened to one robot's tether: ``kind`` is ``"attached"`` (started pulling),
    ``"released"`` (commanded), ``"arrived"`` (auto-release in the stop radius), ``"snagged"`` (a wall came
    between cargo and anchor) or ``"blocked"`` (an attachment found no line of sight when it became ready)."""

    time_s: float
    kind: str
    robot: int
    anchor: int

    def to_dict(self) -> dict:
        return {"time": self.time_s, "kind": self.kind, "robot": self.robot, "anchor": self.anchor}


class _Tether:
    __slots__ = ("anchor", "ready_s", "joint", "pulling", "seen_at", "clearance")
    joint: pymunk.SlideJoint | None  # the reel fidelity's joint, from the moment the tether pulls

    def __init__(self, anchor: int, ready_s: float) -> None:
        self.anchor, self.ready_s, self.joint, self.pulling = anchor, ready_s, None, False
        self.seen_at, self.clearance = (math.nan, math.nan), -1.0  # see TetherWorld._check_tethers


def _count_contact(arbiter: pymunk.Arbiter, space: pymunk.Space, world: TetherWorld) -> None:
    world.wall_contacts += 1


class TetherWorld:
    """A fresh pymunk space for one episode of a station.

    Args:
        station: the station to build.
        fidelity: ``"kinematic"``, ``"reel"`` or ``"force"`` (see below).
        pull_speed_mps: the winches' actual reel-in speed ``w``; default the station's (a planner that assumes
            the station's ``w`` meets a mismatch when this differs).
        start_m: the cargo's initial centre; default the station's.
        cache_checks: skip the exact line-of-sight and wall-contact tests while the cargo provably cannot have
            changed their outcome (see :meth:`_check_tethers`); the same trajectories, about twice as fast.

    Robots are numbered ``0 .. station.n_robots - 1``; their tethers are commanded with :meth:`attach` and
    :meth:`release`, which do not check the fleet's rules (``k``, distinct anchors): the environments do.

    Fidelity levels (``fidelity=``):

    - ``"kinematic"``: what the thesis plans with. The cargo has no inertia: every substep its velocity is set so
      that it moves exactly as Eq. (5), ``x' = w * sum_i (a_i - x) / |a_i - x|`` over the pulling anchors ``a_i``,
      integrated by one classical Runge-Kutta (RK4) step; with no tether it stops. One tether: a straight line
      toward the anchor at speed ``w``. Two: the branch of the hyperbola ``|x - a_1| - |x - a_2| = const`` (both
      distances shrink at the same rate ``w (1 + cos theta)``) at speed ``2 w cos(theta / 2)``, ``theta`` the angle
      between the tethers at the cargo. Where the cargo touches a wall, the velocity component into it is dropped
      (it slides, frictionless).
    - ``"reel"``: each tether is a pymunk slide joint whose maximum length is set, every substep, to the current
      distance minus ``w dt``, with the joint's ``max_force`` at the winch limit and its error fully corrected in
      one step. So a winch reels in at least at ``w`` whenever its force suffices, can only pull (a slack tether
      exerts nothing), and the cargo keeps its momentum: a released cargo drifts on, and a new tether keeps the
      velocity component across it. Several tethers: the cargo must approach each anchor at ``w`` or faster, so when
      both of two tethers are taut the cargo moves along the bisector at ``w / cos(theta / 2)`` (each distance
      shrinks at exactly ``w``), not at Eq. (5)'s ``2 w cos(theta / 2)``: equal at ``theta = 90 deg``, half of it
      for parallel tethers, and growing without bound toward opposite tethers, where the winch limit takes over.
    - ``"force"``: a tension ``T_i = F_max * clip(1 - v_r,i / w, 0, 1)`` along each tether, ``v_r,i`` the cargo's
      speed toward anchor ``i``: full winch force from rest, none once the cargo approaches at ``w``. One tether
      from rest: ``v_n = w (1 - (1 - g)^n)`` after ``n`` substeps, ``g = dt F_max / (m w)`` (pymunk's semi-implicit
      Euler step); continuous time constant ``m w / F_max``. Several tethers settle where no tether pulls, as in
      ``reel`` (each distance shrinking at ``w``).

    Every substep, after the physics step, a tether is released when the cargo centre is within the stop radius of
    its anchor (event ``"arrived"``), and snags when a wall comes between the cargo centre and its anchor (event
    ``"snagged"``: the tether is released; :meth:`Station.line_of_sight` is the test, so touching a corner does not
    snag, crossing it does). An attachment commanded with a delay (the attach time ``t_switch``) starts pulling at
    the first substep at or after its ready time, if its anchor is in line of sight then (else ``"blocked"``).

    Winch work (J): the work the tethers do on the cargo, per tether and substep ``J_i . (v_before + v_after) / 2``
    (``J_i`` its impulse vector), which sums over the tethers to the step's change of kinetic energy exactly when no
    wall is touched; :attr:`TetherWorld.winch_work_J` adds the positive parts (a winch does not recover energy).
    Under ``kinematic`` the impulse is what it takes to give the cargo's mass the velocity of Eq. (5).
    """

    def __init__(self, station: Station, fidelity: str = "kinematic", pull_speed_mps: float | None = None,
                 start_m: tuple[float, float] | None = None, cache_checks: bool = True) -> None:
        if fidelity not in FIDELITIES:
            raise TetherError(f"fidelity must be one of {FIDELITIES}, got {fidelity!r}")
        w = station.pull_speed_mps if pull_speed_mps is None else float(pull_speed_mps)
        if not (math.isfinite(w) and w > 0):
            raise TetherError(f"pull_speed_mps must be a finite number > 0, got {pull_speed_mps!r}")
        self.station = station
        self.fidelity = fidelity
        self.w_mps = w
        self.dt_s = station.control_period_s / station.substeps
        self.substeps = station.substeps
        self.n_substeps_done = 0
        self.winch_work_J = 0.0
        self.wall_contacts = 0
        self._mass = station.cargo.mass_kg
        self._winch_N = station.winch_force_limit_N
        self._stop2 = station.stop_radius_m ** 2
        self._anchors = [(float(a.position_m[0]), float(a.position_m[1])) for a in station.anchors]
        ends = np.array(station.walls, dtype=float)  # (n_walls, 2, 2)
        self._wall_a = ends[:, 0]
        self._wall_e = ends[:, 1] - ends[:, 0]
        self._wall_ee = np.einsum("ij,ij->i", self._wall_e, self._wall_e)
        self._notches = station.notches
        self._cache = bool(cache_checks)
        self._wall_seen_at, self._wall_margin = (math.nan, math.nan), -1.0

        space = pymunk.Space()
        space.gravity = (0.0, 0.0)
        space.damping = 1.0
        space.collision_slop = _SLOP_M
        space.iterations = 30  # two taut tethers couple through the cargo: solve them to ~1e-12 (default 10)
        # push overlaps apart within a few steps (pymunk's default leaves 53 % of one after a 0.1 s step); the bias
        # is a separate velocity in pymunk, so it adds no kinetic energy
        space.collision_bias = 1e-10
        self.space = space
        elasticity = math.sqrt(station.restitution)
        r = station.cargo.radius_m
        cargo = pymunk.Body(self._mass, pymunk.moment_for_circle(self._mass, 0.0, r), body_type=pymunk.Body.DYNAMIC)
        cargo.position = station.cargo.start_m if start_m is None else (float(start_m[0]), float(start_m[1]))
        shape = pymunk.Circle(cargo, r)
        shape.elasticity, shape.friction = elasticity, 0.0
        shape.collision_type = 1
        walls = []
        for a, b in station.walls:
            seg = pymunk.Segment(space.static_body, a, b, 0.0)
            seg.elasticity, seg.friction = elasticity, 0.0
            walls.append(seg)
        space.add(cargo, shape, *walls)
        space.on_collision(1, 0, begin=_count_contact, data=self)
        self.cargo = cargo
        self._tethers: list[_Tether | None] = [None] * station.n_robots
        self._events: list[TetherEvent] = []

    # ---------------------------------------------------------------------------------------- state
    @property
    def time_s(self) -> float:
        return self.n_substeps_done * self.dt_s

    @property
    def position_m(self) -> tuple[float, float]:
        p = self.cargo.position
        return (p.x, p.y)

    @property
    def velocity_mps(self) -> tuple[float, float]:
        v = self.cargo.velocity
        return (v.x, v.y)

    def tether_anchor(self, robot: int) -> int | None:
        """The anchor robot ``robot`` holds (pulling or attaching), or None."""
        t = self._tethers[robot]
        return None if t is None else t.anchor

    def is_pulling(self, robot: int) -> bool:
        t = self._tethers[robot]
        return t is not None and t.pulling

    def attach_remaining_s(self, robot: int) -> float:
        """Time (s) until an attaching robot's tether pulls; 0 when it pulls or holds nothing."""
        t = self._tethers[robot]
        return 0.0 if t is None or t.pulling else max(0.0, t.ready_s - self.time_s)

    def tether_length_m(self, robot: int) -> float:
        """Distance (m) from the cargo centre to the robot's anchor; 0 when it holds none."""
        t = self._tethers[robot]
        if t is None:
            return 0.0
        p, (ax, ay) = self.cargo.position, self._anchors[t.anchor]
        return math.hypot(ax - p.x, ay - p.y)

    def pulling_anchors(self) -> list[int]:
        return [t.anchor for t in self._tethers if t is not None and t.pulling]

    # ------------------------------------------------------------------------------------- commands
    def attach(self, robot: int, anchor: int, delay_s: float = 0.0) -> None:
        """Robot ``robot`` attaches to ``anchor``; its tether pulls from ``delay_s`` seconds on (the attach time)."""
        if not 0 <= robot < len(self._tethers):
            raise TetherError(f"robot must be in 0..{len(self._tethers) - 1}, got {robot}")
        if not 0 <= anchor < len(self._anchors):
            raise TetherError(f"anchor must be in 0..{len(self._anchors) - 1}, got {anchor}")
        held = self._tethers[robot]
        if held is not None:
            raise TetherError(f"robot {robot} already holds anchor {held.anchor}; release it first")
        tether = _Tether(anchor, self.time_s + max(0.0, float(delay_s)))
        self._tethers[robot] = tether
        if tether.ready_s <= self.time_s + 1e-12:
            self._activate(robot, tether)

    def release(self, robot: int, kind: str = "released") -> None:
        """Let go of the robot's tether at once (nothing happens if it holds none)."""
        t = self._tethers[robot]
        if t is None:
            return
        if t.joint is not None:
            self.space.remove(t.joint)
        self._tethers[robot] = None
        self._events.append(TetherEvent(self.time_s, kind, robot, t.anchor))

    def _activate(self, robot: int, t: _Tether) -> None:
        x, y = self.position_m
        if not self.station.line_of_sight((x, y), [t.anchor])[0]:
            self._tethers[robot] = None
            self._events.append(TetherEvent(self.time_s, "blocked", robot, t.anchor))
            return
        ax, ay = self._anchors[t.anchor]
        if (ax - x) ** 2 + (ay - y) ** 2 <= self._stop2:
            self._tethers[robot] = None
            self._events.append(TetherEvent(self.time_s, "arrived", robot, t.anchor))
            return
        t.pulling = True
        if self.fidelity == "reel":
            joint = pymunk.SlideJoint(self.space.static_body, self.cargo, (ax, ay), (0.0, 0.0), 0.0,
                                      math.hypot(ax - x, ay - y))
            joint.max_force = self._winch_N
            joint.error_bias = 0.0  # correct the whole length error in one step: the winch reels in at w
            self.space.add(joint)
            t.joint = joint
        self._events.append(TetherEvent(self.time_s, "attached", robot, t.anchor))

    # ----------------------------------------------------------------------------------------- step
    def step(self) -> list[TetherEvent]:
        """Advance one control period (``substeps`` physics steps); returns the tether events in it."""
        for _ in range(self.substeps):
            self._substep()
        events, self._events = self._events, []
        return events

    def _substep(self) -> None:
        active = [t for t in self._tethers if t is not None and t.pulling]
        cargo, dt, w = self.cargo, self.dt_s, self.w_mps
        p, v0 = cargo.position, cargo.velocity
        x, y, vx0, vy0 = p.x, p.y, v0.x, v0.y
        units = []
        for t in active:
            ax, ay = self._anchors[t.anchor]
            d = math.hypot(ax - x, ay - y)
            units.append(((ax - x) / d, (ay - y) / d, d))
        if self.fidelity == "kinematic":
            if active:
                nx, ny = _rk4_eq5(x, y, [self._anchors[t.anchor] for t in active], w, dt)
                vx, vy = self._slide_along_walls(x, y, (nx - x) / dt, (ny - y) / dt)
            else:
                vx = vy = 0.0
            cargo.velocity = (vx, vy)
            # the impulse the tethers give the cargo, shared out by nothing finer than their sum
            gain = 0.5 * self._mass * (vx * vx + vy * vy - vx0 * vx0 - vy0 * vy0)
            if gain > 0.0:
                self.winch_work_J += gain
            vx0, vy0 = vx, vy
            self.space.step(dt)
        elif self.fidelity == "reel":
            # pymunk moves the bodies first and then solves the joints at the moved positions: the length error
            # it then sees is w dt exactly when the limit is taken from the predicted position
            px, py = x + vx0 * dt, y + vy0 * dt
            units = []
            for t in active:
                ax, ay = self._anchors[t.anchor]
                d = math.hypot(ax - px, ay - py)
                units.append(((ax - px) / d, (ay - py) / d, d))
                t.joint.max = max(0.0, d - w * dt)  # type: ignore[union-attr]  # reel: a pulling tether's joint
            self.space.step(dt)
            v1 = cargo.velocity
            mx, my = 0.5 * (vx0 + v1.x), 0.5 * (vy0 + v1.y)
            for t, (ux, uy, _) in zip(active, units):
                work = t.joint.impulse * (ux * mx + uy * my)  # type: ignore[union-attr]  # as above
                if work > 0.0:
                    self.winch_work_J += work
        else:
            fx = fy = 0.0
            tensions = []
            for ux, uy, _ in units:
                shortfall = 1.0 - (vx0 * ux + vy0 * uy) / w
                tension = self._winch_N * (0.0 if shortfall < 0.0 else (1.0 if shortfall > 1.0 else shortfall))
                tensions.append(tension)
                fx += tension * ux
                fy += tension * uy
            cargo.force = (fx, fy)
            self.space.step(dt)
            v1 = cargo.velocity
            mx, my = 0.5 * (vx0 + v1.x), 0.5 * (vy0 + v1.y)
            for tension, (ux, uy, _) in zip(tensions, units):
                work = tension * dt * (ux * mx + uy * my)
                if work > 0.0:
                    self.winch_work_J += work
        self.n_substeps_done += 1
        if active:
            self._check_tethers()
        for robot, waiting in enumerate(self._tethers):
            if waiting is not None and not waiting.pulling and waiting.ready_s <= self.time_s + 1e-9:
                self._activate(robot, waiting)

    def _slide_along_walls(self, x: float, y: float, vx: float, vy: float) -> tuple[float, float]:
        """Eq. (5) without inertia meets a wall: drop the velocity component into each wall the cargo touches.

        The cargo then slides along the wall (no friction) instead of being driven into it every substep, which
        pymunk's contacts would only undo a step later.
        """
        sx, sy = self._wall_seen_at
        if self._cache and math.hypot(x - sx, y - sy) < self._wall_margin:
            return vx, vy  # farther from every wall than the cargo has moved since they were measured
        rel = np.array([x, y]) - self._wall_a
        s = np.clip(np.einsum("ij,ij->i", rel, self._wall_e) / self._wall_ee, 0.0, 1.0)
        away = rel - s[:, None] * self._wall_e  # from the nearest wall point to the centre
        dist = np.hypot(away[:, 0], away[:, 1])
        reach = self.station.cargo.radius_m + 2.0 * _SLOP_M
        self._wall_seen_at, self._wall_margin = (x, y), float(dist.min()) - reach
        touching = np.flatnonzero(dist <= reach)
        for _ in range(2):  # two passes settle a corner (two walls)
            for i in touching:
                nx, ny = away[i] / dist[i]
                into = -(vx * nx + vy * ny)
                if into > 0.0:
                    vx, vy = vx + into * nx, vy + into * ny
        return vx, vy

    def _check_tethers(self) -> None:
        """Release tethers inside their stop radius ("arrived") and those a wall has come across ("snagged").

        A visible tether can only lose its line of sight when the segment from the cargo to the anchor sweeps
        over a notch (a reflex vertex): touching an edge's inside, or a convex corner, from the interior means
        crossing it, so the first contact is at a notch. Every point of that segment moves at most as far as the
        cargo does (the anchor end is fixed), so while the cargo stays within the segment's distance to the
        nearest notch, measured at the last exact test, the tether is still in sight and the shapely test is
        skipped.
        """
        x, y = self.position_m
        held, exact = [], []
        for robot, t in enumerate(self._tethers):
            if t is None or not t.pulling:
                continue
            ax, ay = self._anchors[t.anchor]
            if (ax - x) ** 2 + (ay - y) ** 2 <= self._stop2:
                self.release(robot, "arrived")
                continue
            sx, sy = t.seen_at
            if not (self._cache and math.hypot(x - sx, y - sy) < t.clearance):
                held.append((robot, t))
                exact.append(t.anchor)
        if not held:
            return
        for (robot, t), visible in zip(held, self.station.line_of_sight((x, y), exact)):
            if not visible:
                self.release(robot, "snagged")
            elif self._cache:
                t.seen_at, t.clearance = (x, y), self._notch_clearance(x, y, *self._anchors[t.anchor])

    def _notch_clearance(self, x: float, y: float, ax: float, ay: float) -> float:
        """Distance (m) from the segment cargo-anchor to the nearest notch (inf without notches)."""
        notches = self._notches
        if len(notches) == 0:
            return math.inf
        ex, ey = ax - x, ay - y
        rx, ry = notches[:, 0] - x, notches[:, 1] - y
        s = np.clip((rx * ex + ry * ey) / (ex * ex + ey * ey), 0.0, 1.0)
        return float(np.hypot(rx - s * ex, ry - s * ey).min())


def eq5_velocity(x: float, y: float, anchors: list[tuple[float, float]], w: float) -> tuple[float, float]:
    """Eq. (5): ``w`` times the sum of the unit vectors from (x, y) toward the anchors (m/s)."""
    vx = vy = 0.0
    for ax, ay in anchors:
        dx, dy = ax - x, ay - y
        d = math.hypot(dx, dy)
        vx += dx / d
        vy += dy / d
    return w * vx, w * vy


def _rk4_eq5(x: float, y: float, anchors: list[tuple[float, float]], w: float, dt: float) -> tuple[float, float]:
    k1 = eq5_velocity(x, y, anchors, w)
    k2 = eq5_velocity(x + 0.5 * dt * k1[0], y + 0.5 * dt * k1[1], anchors, w)
    k3 = eq5_velocity(x + 0.5 * dt * k2[0], y + 0.5 * dt * k2[1], anchors, w)
    k4 = eq5_velocity(x + dt * k3[0], y + dt * k3[1], anchors, w)
    return (x + dt / 6.0 * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0]),
            y + dt / 6.0 * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1]))


def eq5_rk4_path(start: tuple[float, float], anchors: list[tuple[float, float]], w: float, dt: float,
                 steps: int) -> np.ndarray:
    """(steps + 1, 2) positions of Eq. (5) from ``start`` by RK4 steps of ``dt`` (planners' and tests' reference)."""
    out = [tuple(start)]
    x, y = start
    for _ in range(steps):
        x, y = _rk4_eq5(x, y, anchors, w, dt)
        out.append((x, y))
    return np.array(out)
