"""The pymunk world of a station: a free-floating cargo disc pulled by tethers toward wall anchors.

Conventions of the impact world (:mod:`impact_env.transport.physics`): no gravity, ``space.damping = 1.0`` (no
damping; pymunk's damping is a retention factor), zero friction, every shape gets ``sqrt(e)`` so a cargo-wall
contact bounces with exactly the station's restitution ``e``, collision slop 0.1 mm, and a fresh space per
episode. The station's walls are static segments; the cargo is a dynamic disc; each tether joins the cargo's
centre to its anchor and either reels in or holds (its winch brakes). How a tether pulls depends on the fidelity
(``"kinematic"``: the thesis's Eq. (5) exactly; ``"reel"``: slide joints reeled in at ``w``; ``"force"``: a
saturating winch tension), and its events (attached, released, arrived, snagged, blocked, and the faults) and
the winch work are counted the same way in all three: :class:`TetherWorld` describes each. The substep loop
calls chipmunk's C functions where pymunk exposes them (its Python properties cost more than the physics at this
size), as the impact world does, and at ``kinematic`` fidelity runs in C where that is built
(:mod:`impact_env.tether.native`); every path gives bit-identical trajectories
(``tests/impact_env/tether/test_fast_path.py``, ``test_native_parity.py``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pymunk

from impact_env.errors import TetherError
from impact_env.tether import native
from impact_env.tether.sight import distance_to_rays, shadow_rays
from impact_env.tether.station import Station

try:  # the C functions behind pymunk's properties, for the hot loop (see TetherWorld.step)
    from pymunk._chipmunk import lib as _cp
except ImportError:  # pragma: no cover - a pymunk build without the cffi module: public API only
    _cp = None

FIDELITIES = ("kinematic", "reel", "force")
EVENT_KINDS = ("attached", "released", "arrived", "snagged", "blocked", "refused", "anchor_failed", "snapped",
               "dropped_out")
_SLOP_M = 1e-4
_CHECK_MARGIN_M = 1e-9  # the stop-radius and sight budgets end this much early (rounding of the exact tests)


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


class _Tether:
    __slots__ = ("anchor", "ax", "ay", "ready_s", "joint", "jptr", "pulling", "held", "w", "seen_at", "clearance",
                 "length")
    joint: pymunk.SlideJoint | None  # the reel fidelity's joint, from the moment the tether pulls
    jptr: Any  # what the reel loop drives: the joint's chipmunk pointer on the fast path, else the joint (or None)

    def __init__(self, anchor: int, position: tuple[float, float], ready_s: float, w: float) -> None:
        self.anchor, self.ready_s, self.joint, self.jptr, self.pulling = anchor, ready_s, None, None, False
        self.ax, self.ay = position
        self.held = False  # the winch holds the tether at its length instead of reeling in
        self.length = math.inf  # a held tether's length (m), set when the hold starts
        self.w = w  # this robot's reel-in speed (m/s)
        self.seen_at, self.clearance = (math.nan, math.nan), -1.0  # see TetherWorld._check_tethers

    def slide_joint(self) -> pymunk.SlideJoint:
        """The reel fidelity's joint of a pulling tether (the public-API path drives it through pymunk)."""
        if self.joint is None:
            raise TetherError(f"the tether to anchor {self.anchor} has no joint: only a pulling tether of the reel "
                              "fidelity has one")
        return self.joint


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
        winch_speeds_mps: each robot's own reel-in speed (a winch speed error); default ``pull_speed_mps`` for all.
        fast: step through chipmunk's C functions, and at ``kinematic`` through the compiled substep loop where
            it is built (bit-identical to pymunk's properties, which ``False`` uses).

    Robots are numbered ``0 .. station.n_robots - 1``; their tethers are commanded with :meth:`attach`,
    :meth:`release`, :meth:`hold` and :meth:`reel`, which do not check the fleet's rules (``k``, distinct
    anchors): the environments do. The faults are :meth:`fail_anchor`, :meth:`snap` and :meth:`drop_out`.

    Fidelity levels (``fidelity=``):

    - ``"kinematic"``: what the thesis plans with. The cargo has no inertia: every substep its velocity is set so
      that it moves exactly as Eq. (5), ``x' = w * sum_i (a_i - x) / |a_i - x|`` over the reeling anchors ``a_i``,
      integrated by one classical Runge-Kutta (RK4) step; with no reeling tether it stops. One tether: a straight
      line toward the anchor at speed ``w``. Two: the branch of the hyperbola ``|x - a_1| - |x - a_2| = const``
      (both distances shrink at the same rate ``w (1 + cos theta)``) at speed ``2 w cos(theta / 2)``, ``theta`` the
      angle between the tethers at the cargo. Where the cargo touches a wall, the velocity component into it is
      dropped (it slides, frictionless); a held tether drops the component away from its anchor.
    - ``"reel"``: each tether is a pymunk slide joint whose maximum length is set, every substep, to the current
      distance minus ``w dt``, with the joint's ``max_force`` at the winch limit and its error fully corrected in
      one step. So a winch reels in at least at ``w`` whenever its force suffices, can only pull (a slack tether
      exerts nothing), and the cargo keeps its momentum: a released cargo drifts on, and a new tether keeps the
      velocity component across it. Several tethers: the cargo must approach each anchor at ``w`` or faster, so when
      both of two tethers are taut the cargo moves along the bisector at ``w / cos(theta / 2)`` (each distance
      shrinks at exactly ``w``), not at Eq. (5)'s ``2 w cos(theta / 2)``: equal at ``theta = 90 deg``, half of it
      for parallel tethers, and growing without bound toward opposite tethers, where the winch limit takes over.
      A held tether keeps its length: it stops, within the winch limit, a cargo moving away from its anchor,
      and does not pull it back (a locked drum, not a spring: the joint corrects no length error).
    - ``"force"``: a tension ``T_i = F_max * clip(1 - v_r,i / w, 0, 1)`` along each reeling tether, ``v_r,i`` the
      cargo's speed toward anchor ``i``: full winch force from rest, none once the cargo approaches at ``w``. One
      tether from rest: ``v_n = w (1 - (1 - g)^n)`` after ``n`` substeps, ``g = dt F_max / (m w)`` (pymunk's
      semi-implicit Euler step); continuous time constant ``m w / F_max``. Several tethers settle where no tether
      pulls, as in ``reel`` (each distance shrinking at ``w``). A held tether is the same speed control with the
      set point 0: ``T = F_max * clip(-v_r / w, 0, 1)``, a brake that stops a cargo moving away from the anchor
      with the time constant ``m w / F_max``.

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
        self._tethers: list[_Tether | None] = [None] * station.n_robots
        self._events: list[TetherEvent] = []
        self.changes = 0  # counts every change of a robot's tether (attach, start, hold, reel, release)
        self._active: list[_Tether] | None = None  # the pulling tethers in robot order; None: to be rebuilt
        self._next_ready = math.inf  # the earliest ready time of an attaching tether
        self._budget = -1.0  # how far the cargo may move from _checked_at before a tether check can change anything
        self._checked_at = (math.nan, math.nan)
        self._fast = _cp is not None and bool(fast)
        if self._fast:
            self._body_ptr, self._space_ptr = cargo._body, space._space
        # the kinematic substeps in C where it is built (impact_env.tether.native), else _step_kinematic_fast
        self._kinematic_loop = native.kinematic_loop(space, cargo, self.dt_s, self._winch_N) \
            if self._fast and fidelity == "kinematic" else None
        self._planned: list[_Tether] | None = None  # the active list the loop's plan was made from

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

    def state(self) -> tuple[float, float, float, float]:
        """(x, y, vx, vy) of the cargo (m, m/s)."""
        if self._fast:
            p, v = _cp.cpBodyGetPosition(self._body_ptr), _cp.cpBodyGetVelocity(self._body_ptr)
        else:
            p, v = self.cargo.position, self.cargo.velocity
        return (p.x, p.y, v.x, v.y)

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
        tether = _Tether(anchor, self._anchors[anchor], self.time_s + max(0.0, float(delay_s)),
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

    def _brake(self, t: _Tether, length: float) -> None:
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

    def _activate(self, robot: int, t: _Tether) -> None:
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

    # ----------------------------------------------------------------------------------------- step
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

    # The three loops below are _substep() for one fidelity each, written out with the C calls and with the
    # cargo's state carried from one substep to the next (nothing between two physics steps moves it), the same
    # arithmetic in the same order: the trajectories are bit-identical to _substep's. pymunk's own step() would
    # also lock the space for its callbacks; the one callback here (a contact count) adds and removes nothing.

    def _begin_fast(self) -> tuple:
        if self._active is None:
            self._active = [t for t in self._tethers if t is not None and t.pulling]
            self._budget = -1.0
        p, v = _cp.cpBodyGetPosition(self._body_ptr), _cp.cpBodyGetVelocity(self._body_ptr)
        return p.x, p.y, v.x, v.y

    def _after_substep_fast(self, active: list[_Tether], x: float, y: float) -> None:
        """The tether checks and the attachments that become ready after a physics step, cargo at (x, y)."""
        if active:
            cx, cy = self._checked_at
            if not math.hypot(x - cx, y - cy) < self._budget:
                self._check_tethers(active)
        if self._next_ready <= self.n_substeps_done * self.dt_s + 1e-9:
            self._activate_ready()

    def _step_reel_fast(self) -> None:
        cp, body, space, dt, hypot = _cp, self._body_ptr, self._space_ptr, self.dt_s, math.hypot
        get_pos, get_vel, set_max, step, impulse = (cp.cpBodyGetPosition, cp.cpBodyGetVelocity, cp.cpSlideJointSetMax,
                                                    cp.cpSpaceStep, cp.cpConstraintGetImpulse)
        x, y, vx0, vy0 = self._begin_fast()
        total = self.winch_work_J  # the same additions in the same order as _substep's, kept in a local
        n = self.n_substeps_done
        pair = None  # the two pulling tethers' constants, the common case written out below
        for _ in range(self.substeps):
            active = self._active
            if active is None:
                active = self._active = [t for t in self._tethers if t is not None and t.pulling]
                self._budget = -1.0
            px, py = x + vx0 * dt, y + vy0 * dt
            if len(active) == 2:
                if pair is None or pair[0] is not active:
                    t1, t2 = active
                    pair = (active, t1.ax, t1.ay, t1.jptr, None if t1.held else t1.w * dt,
                            t2.ax, t2.ay, t2.jptr, None if t2.held else t2.w * dt)
                _, a1x, a1y, j1, s1, a2x, a2y, j2, s2 = pair
                d = hypot(a1x - px, a1y - py)
                u1x, u1y = (a1x - px) / d, (a1y - py) / d
                if s1 is not None:
                    set_max(j1, max(0.0, d - s1))
                d = hypot(a2x - px, a2y - py)
                u2x, u2y = (a2x - px) / d, (a2y - py) / d
                if s2 is not None:
                    set_max(j2, max(0.0, d - s2))
                step(space, dt)
                v = get_vel(body)
                vx1, vy1 = v.x, v.y
                p = get_pos(body)
                x, y = p.x, p.y
                n += 1
                mx, my = 0.5 * (vx0 + vx1), 0.5 * (vy0 + vy1)
                work = impulse(j1) * (u1x * mx + u1y * my)
                if work > 0.0:
                    total += work
                work = impulse(j2) * (u2x * mx + u2y * my)
                if work > 0.0:
                    total += work
            else:
                units = []
                for t in active:
                    ax, ay = t.ax, t.ay
                    d = hypot(ax - px, ay - py)
                    units.append(((ax - px) / d, (ay - py) / d))
                    if not t.held:
                        set_max(t.jptr, max(0.0, d - t.w * dt))
                step(space, dt)
                v = get_vel(body)
                vx1, vy1 = v.x, v.y
                p = get_pos(body)
                x, y = p.x, p.y
                n += 1
                if active:
                    mx, my = 0.5 * (vx0 + vx1), 0.5 * (vy0 + vy1)
                    for t, (ux, uy) in zip(active, units):
                        work = impulse(t.jptr) * (ux * mx + uy * my)
                        if work > 0.0:
                            total += work
            if active:
                cx, cy = self._checked_at
                if not hypot(x - cx, y - cy) < self._budget:
                    self.n_substeps_done, self.winch_work_J = n, total
                    self._check_tethers(active)
            vx0, vy0 = vx1, vy1
            if self._next_ready <= n * dt + 1e-9:
                self.n_substeps_done, self.winch_work_J = n, total
                self._activate_ready()
        self.n_substeps_done, self.winch_work_J = n, total

    def _step_force_fast(self) -> None:
        cp, body, space, dt, hypot = _cp, self._body_ptr, self._space_ptr, self.dt_s, math.hypot
        get_pos, get_vel, set_force = cp.cpBodyGetPosition, cp.cpBodyGetVelocity, cp.cpBodySetForce
        step = cp.cpSpaceStep
        winch = self._winch_N
        x, y, vx0, vy0 = self._begin_fast()
        for _ in range(self.substeps):
            active = self._active
            if active is None:
                active = self._active = [t for t in self._tethers if t is not None and t.pulling]
                self._budget = -1.0
            fx = fy = 0.0
            tensions = []
            for t in active:
                ax, ay = t.ax, t.ay
                d = hypot(ax - x, ay - y)
                ux, uy = (ax - x) / d, (ay - y) / d
                shortfall = (0.0 if t.held else 1.0) - (vx0 * ux + vy0 * uy) / t.w
                tension = winch * (0.0 if shortfall < 0.0 else (1.0 if shortfall > 1.0 else shortfall))
                tensions.append((tension, ux, uy))
                fx += tension * ux
                fy += tension * uy
            set_force(body, (fx, fy))
            step(space, dt)
            v = get_vel(body)
            vx1, vy1 = v.x, v.y
            if active:
                mx, my = 0.5 * (vx0 + vx1), 0.5 * (vy0 + vy1)
                for tension, ux, uy in tensions:
                    work = tension * dt * (ux * mx + uy * my)
                    if work > 0.0:
                        self.winch_work_J += work
            self.n_substeps_done += 1
            p = get_pos(body)
            x, y, vx0, vy0 = p.x, p.y, vx1, vy1
            self._after_substep_fast(active, x, y)

    def _step_kinematic_native(self) -> None:
        """:meth:`_step_kinematic_fast` with its substeps in C (:mod:`impact_env.tether.native`). The loop runs
        while nothing but arithmetic is needed; the substeps that need the wall test (or meet a cargo at an
        anchor) run here in Python, as do the tether checks and attachments once due, with the same state."""
        loop, dt, hypot = self._kinematic_loop, self.dt_s, math.hypot
        assert loop is not None  # the caller runs this only with the compiled loop
        end = self.n_substeps_done + self.substeps
        while self.n_substeps_done < end:
            active = self._active
            if active is None:
                active = self._active = [t for t in self._tethers if t is not None and t.pulling]
                self._budget = -1.0
            if self._planned is not active:  # every change of the tethers makes a new active list
                reeling = [t for t in active if not t.held]
                w = reeling[0].w if reeling else 0.0
                same = all(t.w == w for t in reeling)
                loop.set_plan([(t.ax, t.ay) for t in reeling], w, None if same else [t.w for t in reeling],
                              [(t.ax, t.ay, t.length) for t in active if t.held], bool(active))
                self._planned = active
            (cx, cy), (sx, sy) = self._checked_at, self._wall_seen_at
            n, self.winch_work_J, stop = loop.run(end - self.n_substeps_done, self.n_substeps_done,
                                                  self.winch_work_J, cx, cy, self._budget, sx, sy,
                                                  self._wall_margin if self._cache else -math.inf,
                                                  self._next_ready)
            self.n_substeps_done = n
            if stop == 1:  # a substep that needs the wall test: Python takes it (and its checks)
                self._step_kinematic_fast(1)
            elif stop == 2:  # the tether checks or attachments are due after the substep just taken
                p = _cp.cpBodyGetPosition(self._body_ptr)
                x, y = p.x, p.y
                if active:
                    cx, cy = self._checked_at
                    if not hypot(x - cx, y - cy) < self._budget:
                        self._check_tethers(active)
                if self._next_ready <= n * dt + 1e-9:
                    self._activate_ready()

    def _step_kinematic_fast(self, substeps: int | None = None) -> None:
        cp, body, space, dt, hypot = _cp, self._body_ptr, self._space_ptr, self.dt_s, math.hypot
        get_pos, set_vel, step = cp.cpBodyGetPosition, cp.cpBodySetVelocity, cp.cpSpaceStep
        winch, cache = self._winch_N, self._cache
        x, y, _, _ = self._begin_fast()
        total = self.winch_work_J
        n = self.n_substeps_done
        plan = None  # what the pulling tethers make of Eq. (5), rebuilt when they change
        for _ in range(self.substeps if substeps is None else substeps):
            active = self._active
            if active is None or plan is None or plan[0] is not active:
                if active is None:
                    active = self._active = [t for t in self._tethers if t is not None and t.pulling]
                    self._budget = -1.0
                reeling = [t for t in active if not t.held]
                held = [t for t in active if t.held]
                w = reeling[0].w if reeling else 0.0
                same = all(t.w == w for t in reeling)
                plan = (active, reeling, held, w, None if same else [t.w for t in reeling],
                        [(t.ax, t.ay) for t in reeling])
            _, reeling, held, w, ws, points = plan
            if reeling:
                if len(points) == 1 and ws is None:
                    nx, ny = _rk4_one(x, y, points[0][0], points[0][1], w, dt)
                elif len(points) == 2 and ws is None:
                    nx, ny = _rk4_two(x, y, points[0][0], points[0][1], points[1][0], points[1][1], w, dt)
                else:
                    nx, ny = _rk4_eq5(x, y, points, w, dt, ws)
                vx, vy = (nx - x) / dt, (ny - y) / dt
                if held:
                    vx, vy = _keep_lengths(x, y, vx, vy, held, dt)
                sx, sy = self._wall_seen_at
                if not (cache and hypot(x - sx, y - sy) < self._wall_margin):
                    vx, vy = self._slide_along_walls(x, y, vx, vy)
                work = 0.0
                for ax, ay in points:
                    ux, uy = ax - x, ay - y
                    rate = (vx * ux + vy * uy) / hypot(ux, uy)
                    if rate > 0.0:
                        work += winch * rate * dt
                total += work
            else:
                vx = vy = 0.0
            set_vel(body, (vx, vy))
            step(space, dt)
            n += 1
            p = get_pos(body)
            x, y = p.x, p.y
            if active:
                cx, cy = self._checked_at
                if not hypot(x - cx, y - cy) < self._budget:
                    self.n_substeps_done, self.winch_work_J = n, total
                    self._check_tethers(active)
                    if self._active is None:
                        plan = None
            if self._next_ready <= n * dt + 1e-9:
                self.n_substeps_done, self.winch_work_J = n, total
                self._activate_ready()
                if self._active is None:
                    plan = None
        self.n_substeps_done, self.winch_work_J = n, total

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

    def _space_step(self, dt: float) -> None:
        if self._fast:
            space = self.space
            space._locked = True  # as pymunk's own step(): callbacks may not add or remove shapes
            try:
                _cp.cpSpaceStep(self._space_ptr, dt)
            finally:
                space._locked = False
        else:
            self.space.step(dt)

    def _velocity_after(self) -> tuple[float, float]:
        v = _cp.cpBodyGetVelocity(self._body_ptr) if self._fast else self.cargo.velocity
        return v.x, v.y

    def _set_max(self, t: _Tether, length: float) -> None:
        if self._fast:
            _cp.cpSlideJointSetMax(t.jptr, length)
        else:
            t.slide_joint().max = length

    def _substep_kinematic(self, active: list[_Tether], x: float, y: float, vx0: float, vy0: float) -> None:
        dt = self.dt_s
        reeling = [t for t in active if not t.held]
        if reeling:
            anchors = [(t.ax, t.ay) for t in reeling]
            w = reeling[0].w
            ws = None if all(t.w == w for t in reeling) else [t.w for t in reeling]
            nx, ny = _rk4_eq5(x, y, anchors, w, dt, ws)
            vx, vy = (nx - x) / dt, (ny - y) / dt
            if len(reeling) < len(active):
                vx, vy = _keep_lengths(x, y, vx, vy, [t for t in active if t.held], dt)
            vx, vy = self._slide_along_walls(x, y, vx, vy)
            # Eq. (5)'s tension: every reeling winch at its limit, times the rate its tether shrinks
            work = 0.0
            for t in reeling:
                ux, uy = t.ax - x, t.ay - y
                rate = (vx * ux + vy * uy) / math.hypot(ux, uy)
                if rate > 0.0:
                    work += self._winch_N * rate * dt
            self.winch_work_J += work
        else:
            vx = vy = 0.0
        if self._fast:
            _cp.cpBodySetVelocity(self._body_ptr, (vx, vy))
        else:
            self.cargo.velocity = (vx, vy)
        self._space_step(dt)

    def _substep_reel(self, active: list[_Tether], x: float, y: float, vx0: float, vy0: float) -> None:
        # pymunk moves the bodies first and then solves the joints at the moved positions: the length error it
        # then sees is w dt exactly when the limit is taken from the predicted position
        dt = self.dt_s
        px, py = x + vx0 * dt, y + vy0 * dt
        units = []
        for t in active:
            ax, ay = t.ax, t.ay
            d = math.hypot(ax - px, ay - py)
            units.append(((ax - px) / d, (ay - py) / d))
            if not t.held:
                self._set_max(t, max(0.0, d - t.w * dt))
        self._space_step(dt)
        vx1, vy1 = self._velocity_after()
        mx, my = 0.5 * (vx0 + vx1), 0.5 * (vy0 + vy1)
        fast = self._fast
        for t, (ux, uy) in zip(active, units):
            impulse = _cp.cpConstraintGetImpulse(t.jptr) if fast else t.slide_joint().impulse
            work = impulse * (ux * mx + uy * my)
            if work > 0.0:
                self.winch_work_J += work

    def _substep_force(self, active: list[_Tether], x: float, y: float, vx0: float, vy0: float) -> None:
        dt = self.dt_s
        fx = fy = 0.0
        tensions = []
        for t in active:
            ax, ay = t.ax, t.ay
            d = math.hypot(ax - x, ay - y)
            ux, uy = (ax - x) / d, (ay - y) / d
            # a held winch is the same speed control with the set point 0
            shortfall = (0.0 if t.held else 1.0) - (vx0 * ux + vy0 * uy) / t.w
            tension = self._winch_N * (0.0 if shortfall < 0.0 else (1.0 if shortfall > 1.0 else shortfall))
            tensions.append((tension, ux, uy))
            fx += tension * ux
            fy += tension * uy
        if self._fast:
            _cp.cpBodySetForce(self._body_ptr, (fx, fy))
        else:
            self.cargo.force = (fx, fy)
        self._space_step(dt)
        vx1, vy1 = self._velocity_after()
        mx, my = 0.5 * (vx0 + vx1), 0.5 * (vy0 + vy1)
        for tension, ux, uy in tensions:
            work = tension * dt * (ux * mx + uy * my)
            if work > 0.0:
                self.winch_work_J += work

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
        return float(vx), float(vy)  # numpy's scalars would carry into the winch work and the info

    def _check_tethers(self, active: list[_Tether]) -> None:
        """Release tethers inside their stop radius ("arrived") and those a wall has come across ("snagged").

        A visible tether can only lose its line of sight when the segment from the cargo to the anchor sweeps
        over a notch (a reflex vertex): touching an edge's inside, or a convex corner, from the interior means
        crossing it, so the first contact is at a notch, and the segment passes through a notch exactly when the
        cargo is on the ray from the anchor through that notch, beyond it. So while the cargo stays closer to
        where it was last tested exactly than to any such ray, the tether is still in sight and the shapely test
        is skipped. One budget covers every pulling tether: how far the cargo may move before any tether could
        reach its stop radius or need an exact test, so most substeps check one distance.
        """
        x, y = self.state()[:2]
        cx, cy = self._checked_at
        if math.hypot(x - cx, y - cy) < self._budget:
            return
        held, exact = [], []
        for robot, t in enumerate(self._tethers):
            if t is None or not t.pulling:
                continue
            ax, ay = t.ax, t.ay
            if (ax - x) ** 2 + (ay - y) ** 2 <= self._stop2:
                self.release(robot, "arrived")
                continue
            sx, sy = t.seen_at
            if not (self._cache and math.hypot(x - sx, y - sy) < t.clearance):
                held.append((robot, t))
                exact.append(t.anchor)
        if held:
            for (robot, t), visible in zip(held, self.station.sees(x, y, exact)):
                if not visible:
                    self.release(robot, "snagged")
                elif self._cache:
                    t.seen_at, t.clearance = (x, y), self._notch_clearance(x, y, t.anchor)
        self._checked_at = (x, y)
        budget = math.inf if self._cache else -1.0
        for t in self._tethers:
            if t is not None and t.pulling and budget > 0.0:
                sx, sy = t.seen_at
                stop = math.hypot(t.ax - x, t.ay - y) - self._stop
                sight = t.clearance - math.hypot(x - sx, y - sy)
                budget = min(budget, stop, sight)
        self._budget = budget - _CHECK_MARGIN_M

    def _notch_clearance(self, x: float, y: float, anchor: int) -> float:
        """How far (m) the cargo may move from (x, y) before its tether to ``anchor`` could touch a notch: the
        distance to the rays from the notches away from the anchor (:mod:`impact_env.tether.sight`)."""
        if anchor in self._notch_rays:
            rays = self._notch_rays[anchor]
        else:
            rays = self._notch_rays[anchor] = shadow_rays(np.asarray(self._anchors[anchor]), self._notches)
        return distance_to_rays(x, y, rays)


def _keep_lengths(x: float, y: float, vx: float, vy: float, held: list[_Tether], dt: float) -> tuple[float, float]:
    """The velocity over the next ``dt`` that lengthens no held tether: the component away from each held anchor
    dropped, then the step shortened radially where it would still end farther than the tether's held length
    (moving across a tether lengthens it to second order); two passes settle two of them."""
    for _ in range(2):
        for t in held:
            ux, uy = t.ax - x, t.ay - y
            d = math.hypot(ux, uy)
            ux, uy = ux / d, uy / d
            toward = vx * ux + vy * uy
            if toward < 0.0:
                vx, vy = vx - toward * ux, vy - toward * uy
    for _ in range(2):
        for t in held:
            px, py = x + vx * dt - t.ax, y + vy * dt - t.ay
            d = math.hypot(px, py)
            if d > t.length > 0.0:
                s = t.length / d
                vx, vy = (t.ax + px * s - x) / dt, (t.ay + py * s - y) / dt
    return vx, vy


def eq5_velocity(x: float, y: float, anchors: list[tuple[float, float]], w: float,
                 ws: list[float] | None = None) -> tuple[float, float]:
    """Eq. (5): ``w`` times the sum of the unit vectors from (x, y) toward the anchors (m/s); with ``ws`` each
    anchor's tether reels at its own speed."""
    vx = vy = 0.0
    if ws is None:
        for ax, ay in anchors:
            dx, dy = ax - x, ay - y
            d = math.hypot(dx, dy)
            vx += dx / d
            vy += dy / d
        return w * vx, w * vy
    for (ax, ay), wi in zip(anchors, ws):
        dx, dy = ax - x, ay - y
        d = math.hypot(dx, dy)
        vx += wi * dx / d
        vy += wi * dy / d
    return vx, vy


def _rk4_one(x: float, y: float, ax: float, ay: float, w: float, dt: float) -> tuple[float, float]:
    """:func:`_rk4_eq5` for one anchor, written out (the same operations in the same order)."""
    dx, dy = ax - x, ay - y
    d = math.hypot(dx, dy)
    k1x, k1y = w * (0.0 + dx / d), w * (0.0 + dy / d)
    h = 0.5 * dt
    dx, dy = ax - (x + h * k1x), ay - (y + h * k1y)
    d = math.hypot(dx, dy)
    k2x, k2y = w * (0.0 + dx / d), w * (0.0 + dy / d)
    dx, dy = ax - (x + h * k2x), ay - (y + h * k2y)
    d = math.hypot(dx, dy)
    k3x, k3y = w * (0.0 + dx / d), w * (0.0 + dy / d)
    dx, dy = ax - (x + dt * k3x), ay - (y + dt * k3y)
    d = math.hypot(dx, dy)
    k4x, k4y = w * (0.0 + dx / d), w * (0.0 + dy / d)
    sixth = dt / 6.0
    return (x + sixth * (k1x + 2.0 * k2x + 2.0 * k3x + k4x), y + sixth * (k1y + 2.0 * k2y + 2.0 * k3y + k4y))


def _rk4_two(x: float, y: float, ax: float, ay: float, bx: float, by: float, w: float,
             dt: float) -> tuple[float, float]:
    """:func:`_rk4_eq5` for two anchors reeling at the same speed, written out (the same operations in order)."""
    h = 0.5 * dt
    dx, dy, ex, ey = ax - x, ay - y, bx - x, by - y
    d, e = math.hypot(dx, dy), math.hypot(ex, ey)
    k1x, k1y = w * (0.0 + dx / d + ex / e), w * (0.0 + dy / d + ey / e)
    px, py = x + h * k1x, y + h * k1y
    dx, dy, ex, ey = ax - px, ay - py, bx - px, by - py
    d, e = math.hypot(dx, dy), math.hypot(ex, ey)
    k2x, k2y = w * (0.0 + dx / d + ex / e), w * (0.0 + dy / d + ey / e)
    px, py = x + h * k2x, y + h * k2y
    dx, dy, ex, ey = ax - px, ay - py, bx - px, by - py
    d, e = math.hypot(dx, dy), math.hypot(ex, ey)
    k3x, k3y = w * (0.0 + dx / d + ex / e), w * (0.0 + dy / d + ey / e)
    px, py = x + dt * k3x, y + dt * k3y
    dx, dy, ex, ey = ax - px, ay - py, bx - px, by - py
    d, e = math.hypot(dx, dy), math.hypot(ex, ey)
    k4x, k4y = w * (0.0 + dx / d + ex / e), w * (0.0 + dy / d + ey / e)
    sixth = dt / 6.0
    return (x + sixth * (k1x + 2.0 * k2x + 2.0 * k3x + k4x), y + sixth * (k1y + 2.0 * k2y + 2.0 * k3y + k4y))


def _rk4_eq5(x: float, y: float, anchors: list[tuple[float, float]], w: float, dt: float,
             ws: list[float] | None = None) -> tuple[float, float]:
    k1 = eq5_velocity(x, y, anchors, w, ws)
    k2 = eq5_velocity(x + 0.5 * dt * k1[0], y + 0.5 * dt * k1[1], anchors, w, ws)
    k3 = eq5_velocity(x + 0.5 * dt * k2[0], y + 0.5 * dt * k2[1], anchors, w, ws)
    k4 = eq5_velocity(x + dt * k3[0], y + dt * k3[1], anchors, w, ws)
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
