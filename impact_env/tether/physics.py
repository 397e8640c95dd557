"""The pymunk world of a station: a free-floating cargo disc pulled by tethers toward wall anchors.

Conventions of the impact world (:mod:`impact_env.transport.physics`): no gravity, ``space.damping = 1.0`` (no
damping; pymunk's damping is a retention factor), zero friction, every shape gets ``sqrt(e)`` so a cargo-wall
contact bounces with exactly the station's restitution ``e``, collision slop 0.1 mm, and a fresh space per
episode. The station's walls are static segments; the cargo is a dynamic disc; each tether joins the cargo's
centre to its anchor and either reels in or holds (its winch brakes). How a tether pulls depends on the fidelity
(``"kinematic"``: the thesis's Eq. (5) exactly; ``"reel"``: slide joints reeled in at ``w``; ``"force"``: a
saturating winch tension), and its events (attached, released, arrived, snagged, blocked, and the faults) and
the winch work are counted the same way in all three: :class:`TetherWorld` describes each. This module holds
the world's building, commands and faults; each fidelity's substep loop is its own module
(:mod:`~impact_env.tether.kinematic`, :mod:`~impact_env.tether.reel`, :mod:`~impact_env.tether.force`), on the
tether and wall checks (:mod:`~impact_env.tether.checks`), the plumbing they share
(:mod:`~impact_env.tether.stepping`) and Eq. (5) (:mod:`~impact_env.tether.eq5`). The loops call chipmunk's C
functions where pymunk exposes them (its Python properties cost more than the physics at this size), and at
``kinematic`` fidelity run in C where that is built (:mod:`impact_env.tether.native`); every path gives
bit-identical trajectories (``tests/impact_env/tether/test_fast_path.py``, ``test_native_parity.py``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import pymunk

from impact_env.errors import TetherError
from impact_env.tether import native
from impact_env.tether.eq5 import eq5_rk4_path, eq5_velocity
from impact_env.tether.force import ForceLoop
from impact_env.tether.kinematic import KinematicLoop
from impact_env.tether.reel import ReelLoop
from impact_env.tether.station import Station
from impact_env.tether.stepping import SLOP_M, Tether
from impact_env.tether.stepping import chipmunk_lib as _cp

FIDELITIES = ("kinematic", "reel", "force")
EVENT_KINDS = ("attached", "released", "arrived", "snagged", "blocked", "refused", "anchor_failed", "snapped",
               "dropped_out")


@dataclass(frozen=True)
class TetherEvent:
    """Something that happened to one robot's tether: ``kind`` is ``"attached"`` (started pulling or holding),
    ``"released"`` (commanded), ``"arrived"`` (auto-release in the stop radius), ``"snagged"`` (a wall came
    between cargo and anchor), ``"blocked"`` (an attachment found no line of sight when it became ready),
    ``"refused"`` (an attachment to a failed anchor), ``"anchor_failed"`` (the anchor let go mid-pull),
    ``"snapped"`` (the tether broke) or ``"dropped_out"`` (the robot left the fleet, letting go)."""

    time_s: float
    kind: str
    robot: int
    anchor: int

    def to_dict(self) -> dict:
        return {"time": self.time_s, "kind": self.kind, "robot": self.robot, "anchor": self.anchor}


def _count_contact(arbiter: pymunk.Arbiter, space: pymunk.Space, world: TetherWorld) -> None:
    world.wall_contacts += 1


class TetherWorld(KinematicLoop, ReelLoop, ForceLoop):
    """A fresh pymunk space for one episode of a station.

    Args:
        station: the station to build.
        fidelity: ``"kinematic"``, ``"reel"`` or ``"force"`` (see below).
        pull_speed_mps: the winches' actual reel-in speed ``w``; default the station's (a planner that assumes
            the station's ``w`` meets a mismatch when this differs).
        start_m: the cargo's initial centre; default the station's.
        cache_checks: skip the exact line-of-sight and wall-contact tests while the cargo provably cannot have
            changed their outcome (see :meth:`_check_tethers`); the same trajectories, about twice as fast.
        winch_speeds_mps: each robot's own reel-in speed (a winch speed error); default ``pull_speed_mps`` for all.
        fast: step through chipmunk's C functions, and at ``kinematic`` through the compiled substep loop where
            it is built (bit-identical to pymunk's properties, which ``False`` uses).

    Robots are numbered ``0 .. station.n_robots - 1``; their tethers are commanded with :meth:`attach`,
    :meth:`release`, :meth:`hold` and :meth:`reel`, which do not check the fleet's rules (``k``, distinct
    anchors): the environments do. The faults are :meth:`fail_anchor`, :meth:`snap` and :meth:`drop_out`.

    Fidelity levels (``fidelity=``), each its own substep loop:

    - ``"kinematic"`` (:mod:`impact_env.tether.kinematic`): what the thesis plans with, Eq. (5) exactly; the cargo
      has no inertia.
    - ``"reel"`` (:mod:`impact_env.tether.reel`): each tether a pymunk slide joint reeled in at ``w`` within the
      winch force limit; the cargo keeps its momentum.
    - ``"force"`` (:mod:`impact_env.tether.force`): a tension ``F_max * clip(1 - v_r / w, 0, 1)`` along each
      reeling tether.

    A held tether (:meth:`hold`) keeps its length: it stops, within the winch limit, a cargo moving away from its
    anchor, and does not pull it back.

    Every substep, after the physics step, a tether is released when the cargo centre is within the stop radius of
    its anchor (event ``"arrived"``), and snags when a wall comes between the cargo centre and its anchor (event
    ``"snagged"``: the tether is released; :meth:`Station.line_of_sight` is the test, so touching a corner does not
    snag, crossing it does). An attachment commanded with a delay (the attach time ``t_switch``) starts pulling at
    the first substep at or after its ready time, if its anchor is in line of sight then (else ``"blocked"``) and
    has not failed (else ``"refused"``).

    Winch work (J): what the winches put in, from each tether's tension and its reel-in speed (the rate its length
    shrinks), per substep ``T_i * v_r,i * dt`` with the mean of the substep's radial speeds, the positive parts
    summed into :attr:`TetherWorld.winch_work_J` (a winch does not recover energy; a brake dissipates it). Under
    ``reel`` the tension is the joint's impulse over the substep, under ``force`` the tension law. Under
    ``kinematic`` the tension that is consistent with Eq. (5) is the winch limit: a massless cargo moved at ``w``
    per tether is the overdamped limit of a drag ``F_max / w`` per m/s, against which each reeling winch pulls with
    ``F_max`` (one tether: ``F_max`` times the distance; two at ``theta``: the drag ``2 F_max cos(theta / 2)``
    times the speed ``2 w cos(theta / 2)``).
    """

    def __init__(self, station: Station, fidelity: str = "kinematic", pull_speed_mps: float | None = None,
                 start_m: tuple[float, float] | None = None, cache_checks: bool = True,
                 winch_speeds_mps: Sequence[float] | None = None, fast: bool = True) -> None:
        if fidelity not in FIDELITIES:
            raise TetherError(f"fidelity must be one of {FIDELITIES}, got {fidelity!r}")
        w = station.pull_speed_mps if pull_speed_mps is None else float(pull_speed_mps)
        if not (math.isfinite(w) and w > 0):
            raise TetherError(f"pull_speed_mps must be a finite number > 0, got {pull_speed_mps!r}")
        speeds = [w] * station.n_robots if winch_speeds_mps is None else [float(s) for s in winch_speeds_mps]
        if len(speeds) != station.n_robots or not all(math.isfinite(s) and s > 0 for s in speeds):
            raise TetherError(f"winch_speeds_mps must be {station.n_robots} finite numbers > 0, got "
                              f"{winch_speeds_mps!r}")
        self.station = station
        self.fidelity = fidelity
        self.w_mps = w
        self.winch_speeds_mps = tuple(speeds)
        self.dt_s = station.control_period_s / station.substeps
        self.substeps = station.substeps
        self.n_substeps_done = 0
        self.winch_work_J = 0.0
        self.wall_contacts = 0
        self._mass = station.cargo.mass_kg
        self._winch_N = station.winch_force_limit_N
        self._stop2 = station.stop_radius_m ** 2
        self._stop = station.stop_radius_m
        self._anchors = station.anchor_points
        self._wall_a, self._wall_e, self._wall_ee = station.wall_arrays
        self._notches = station.notches
        self._notch_rays: dict[int, list[tuple[float, float, float, float]] | None] = {}
        self._cache = bool(cache_checks)
        self._wall_seen_at, self._wall_margin = (math.nan, math.nan), -1.0
        self.failed_anchors: set[int] = set()
        self.dropped_robots: set[int] = set()

        space = pymunk.Space()
        space.gravity = (0.0, 0.0)
        space.damping = 1.0
        space.collision_slop = SLOP_M
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
        static = space.static_body
        walls = [pymunk.Segment(static, a, b, 0.0) for a, b in station.walls]
        if _cp is not None and fast:  # the C setters behind pymunk's properties (each property set costs more)
            for s in [shape, *walls]:
                _cp.cpShapeSetElasticity(s._shape, elasticity)
                _cp.cpShapeSetFriction(s._shape, 0.0)
            _cp.cpShapeSetCollisionType(shape._shape, 1)
        else:
            for s in [shape, *walls]:
                s.elasticity, s.friction = elasticity, 0.0
            shape.collision_type = 1
        space.add(cargo, shape, *walls)
        space.on_collision(1, 0, begin=_count_contact, data=self)
        self.cargo = cargo
        self._tethers: list[Tether | None] = [None] * station.n_robots
        self._events: list[TetherEvent] = []
        self.changes = 0  # counts every change of a robot's tether (attach, start, hold, reel, release)
        self._active: list[Tether] | None = None  # the pulling tethers in robot order; None: to be rebuilt
        self._next_ready = math.inf  # the earliest ready time of an attaching tether
        self._budget = -1.0  # how far the cargo may move from _checked_at before a tether check can change anything
        self._checked_at = (math.nan, math.nan)
        self._fast = _cp is not None and bool(fast)
        if self._fast:
            self._body_ptr, self._space_ptr = cargo._body, space._space
        # the kinematic substeps in C where it is built (impact_env.tether.native), else _step_kinematic_fast
        self._kinematic_loop = native.kinematic_loop(space, cargo, self.dt_s, self._winch_N) \
            if self._fast and fidelity == "kinematic" else None
        self._planned: list[Tether] | None = None  # the active list the loop's plan was made from

    def restart(self, start_m: tuple[float, float] | None = None,
                winch_speeds_mps: Sequence[float] | None = None) -> TetherWorld:
        """This world as a fresh one would be (the same trajectories, bit for bit), without rebuilding pymunk.

        What a used space holds beyond a fresh one: the tethers' joints (removed), the cargo's state (set: at
        rest at the start, no force, no rotation), and chipmunk's cache of contacts, which would warm-start a
        contact that resumes within three steps and skip its ``begin``: removing the cargo's shape and adding it
        again drops every cached contact of it, as chipmunk does for any removed shape. The one other difference,
        the previous step length that chipmunk scales cached impulses by (0 in a fresh space), then multiplies
        nothing: no contact is cached and a new joint's impulse starts at 0. The static walls are untouched.
        """
        for t in self._tethers:
            if t is not None and t.joint is not None:
                self.space.remove(t.joint)
        shape = next(iter(self.cargo.shapes))
        self.space.remove(shape)
        self.space.add(shape)
        cargo = self.cargo
        cargo.position = self.station.cargo.start_m if start_m is None else (float(start_m[0]), float(start_m[1]))
        cargo.velocity = (0.0, 0.0)
        cargo.force = (0.0, 0.0)
        cargo.angle = 0.0
        cargo.angular_velocity = 0.0
        cargo.torque = 0.0
        speeds = [self.w_mps] * self.station.n_robots if winch_speeds_mps is None else \
            [float(v) for v in winch_speeds_mps]
        if len(speeds) != self.station.n_robots or not all(math.isfinite(v) and v > 0 for v in speeds):
            raise TetherError(f"winch_speeds_mps must be {self.station.n_robots} finite numbers > 0, got "
                              f"{winch_speeds_mps!r}")
        self.winch_speeds_mps = tuple(speeds)
        self.n_substeps_done = 0
        self.winch_work_J = 0.0
        self.wall_contacts = 0
        self._wall_seen_at, self._wall_margin = (math.nan, math.nan), -1.0
        self.failed_anchors = set()
        self.dropped_robots = set()
        self._tethers = [None] * self.station.n_robots
        self._events = []
        self.changes += 1
        self._active = None
        self._next_ready = math.inf
        self._budget = -1.0
        self._checked_at = (math.nan, math.nan)
        return self

    # ---------------------------------------------------------------------------------------- state
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

    def is_holding(self, robot: int) -> bool:
        """Whether the robot's winch holds its tether (attaching or pulling) instead of reeling in."""
        t = self._tethers[robot]
        return t is not None and t.held

    def attach_remaining_s(self, robot: int) -> float:
        """Time (s) until an attaching robot's tether pulls; 0 when it pulls or holds nothing."""
        t = self._tethers[robot]
        return 0.0 if t is None or t.pulling else max(0.0, t.ready_s - self.time_s)

    def tether_length_m(self, robot: int) -> float:
        """Distance (m) from the cargo centre to the robot's anchor; 0 when it holds none."""
        t = self._tethers[robot]
        if t is None:
            return 0.0
        x, y = self.state()[:2]
        return math.hypot(t.ax - x, t.ay - y)

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
        if robot in self.dropped_robots:
            raise TetherError(f"robot {robot} has dropped out")
        tether = Tether(anchor, self._anchors[anchor], self.time_s + max(0.0, float(delay_s)),
                         self.winch_speeds_mps[robot])
        self._tethers[robot] = tether
        self.changes += 1
        if tether.ready_s <= self.time_s + 1e-12:
            self._activate(robot, tether)
        else:
            self._next_ready = min(self._next_ready, tether.ready_s)

    def release(self, robot: int, kind: str = "released") -> None:
        """Let go of the robot's tether at once (nothing happens if it holds none)."""
        t = self._tethers[robot]
        if t is None:
            return
        if t.joint is not None:
            self.space.remove(t.joint)
        self._tethers[robot] = None
        self._active = None
        self.changes += 1
        self._events.append(TetherEvent(self.time_s, kind, robot, t.anchor))

    def hold(self, robot: int) -> bool:
        """The robot's winch stops reeling and holds its tether at its present length (one that is still attaching
        holds from the moment it attaches); False if the robot holds no tether."""
        t = self._tethers[robot]
        if t is None:
            return False
        if not t.held and t.pulling:
            x, y = self.state()[:2]
            t.length = math.hypot(t.ax - x, t.ay - y)
            if t.jptr is not None:
                self._brake(t, t.length)
        t.held = True
        self.changes += 1
        self._active = None
        return True

    def reel(self, robot: int) -> None:
        """The robot's winch reels in again (after :meth:`hold`)."""
        t = self._tethers[robot]
        if t is not None and t.held:
            t.held = False
            if t.joint is not None:
                t.joint.max_bias = math.inf  # the reel loop shortens it again
            self.changes += 1
            self._active = None

    def _brake(self, t: Tether, length: float) -> None:
        """A held tether under ``reel``: a joint that keeps its present length with no error correction, so it
        stops (within the winch limit) a cargo moving away from the anchor but never pulls it back: a drum that
        is locked, not a spring."""
        self._set_max(t, length)
        t.slide_joint().max_bias = 0.0

    # ---------------------------------------------------------------------------------------- faults
    def fail_anchor(self, anchor: int) -> None:
        """Anchor ``anchor`` breaks: a tether pulling on it lets go (``"anchor_failed"``), and every attachment to
        it from now on is refused (``"refused"``)."""
        self.failed_anchors.add(anchor)
        for robot, t in enumerate(self._tethers):
            if t is not None and t.anchor == anchor and t.pulling:
                self.release(robot, "anchor_failed")

    def snap(self, robot: int) -> bool:
        """The robot's tether breaks (``"snapped"``); the robot may attach again. False if it held none."""
        if self._tethers[robot] is None:
            return False
        self.release(robot, "snapped")
        return True

    def drop_out(self, robot: int) -> None:
        """The robot leaves the fleet: it lets go (``"dropped_out"``) and can no longer attach."""
        if self._tethers[robot] is not None:
            self.release(robot, "dropped_out")
        else:
            self._events.append(TetherEvent(self.time_s, "dropped_out", robot, -1))
        self.dropped_robots.add(robot)

    def _activate(self, robot: int, t: Tether) -> None:
        x, y = self.state()[:2]
        kind = None
        if t.anchor in self.failed_anchors:
            kind = "refused"
        elif not self.station.sees(x, y, [t.anchor])[0]:
            kind = "blocked"
        elif (t.ax - x) ** 2 + (t.ay - y) ** 2 <= self._stop2:
            kind = "arrived"
        self.changes += 1
        if kind is not None:
            self._tethers[robot] = None
            self._events.append(TetherEvent(self.time_s, kind, robot, t.anchor))
            return
        t.pulling = True
        self._active = None
        if self.fidelity == "reel":
            joint = pymunk.SlideJoint(self.space.static_body, self.cargo, (t.ax, t.ay), (0.0, 0.0), 0.0,
                                      math.hypot(t.ax - x, t.ay - y))
            joint.max_force = self._winch_N
            joint.error_bias = 0.0  # correct the whole length error in one step: the winch reels in at w
            self.space.add(joint)
            t.joint = joint
            t.jptr = joint._constraint if self._fast else joint
            if t.held:
                self._brake(t, math.hypot(t.ax - x, t.ay - y))
        if t.held:
            t.length = math.hypot(t.ax - x, t.ay - y)
        self._events.append(TetherEvent(self.time_s, "attached", robot, t.anchor))


    def step(self) -> list[TetherEvent]:
        """Advance one control period (``substeps`` physics steps); returns the tether events in it."""
        if self._fast:
            if self.fidelity == "reel":
                self._step_reel_fast()
            elif self.fidelity == "force":
                self._step_force_fast()
            elif self._kinematic_loop is not None:
                self._step_kinematic_native()
            else:
                self._step_kinematic_fast()
        else:
            substep = self._substep
            for _ in range(self.substeps):
                substep()
        events, self._events = self._events, []
        return events

    def _substep(self) -> None:
        """One physics step of ``dt_s``: the tethers pull, pymunk steps, then the tether checks and attachments."""
        active = self._active
        if active is None:
            active = self._active = [t for t in self._tethers if t is not None and t.pulling]
            self._budget = -1.0
        x, y, vx0, vy0 = self.state()
        if self.fidelity == "reel":
            self._substep_reel(active, x, y, vx0, vy0)
        elif self.fidelity == "force":
            self._substep_force(active, x, y, vx0, vy0)
        else:
            self._substep_kinematic(active, x, y, vx0, vy0)
        self.n_substeps_done += 1
        if active:
            self._check_tethers(active)
        if self._next_ready <= self.time_s + 1e-9:
            self._activate_ready()

    def _activate_ready(self) -> None:
        now = self.time_s
        self._next_ready = math.inf
        for robot, t in enumerate(self._tethers):
            if t is not None and not t.pulling:
                if t.ready_s <= now + 1e-9:
                    self._activate(robot, t)
                else:
                    self._next_ready = min(self._next_ready, t.ready_s)


__all__ = ["EVENT_KINDS", "FIDELITIES", "TetherError", "TetherEvent", "TetherWorld", "eq5_rk4_path", "eq5_velocity"]
