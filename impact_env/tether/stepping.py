"""The tether world's substep plumbing: a tether's state, and what every fidelity's loop shares.

:class:`~impact_env.tether.physics.TetherWorld` is assembled from one class per job: this base (the cargo's
state, the tethers, the pymunk calls a substep makes), the tether and wall checks
(:mod:`impact_env.tether.checks`) and one substep loop per fidelity (:mod:`impact_env.tether.kinematic`,
:mod:`~impact_env.tether.reel`, :mod:`~impact_env.tether.force`). Each loop comes twice: written out with
chipmunk's C functions (the fast path, what the env runs) and through pymunk's public API (``fast=False``), the
same arithmetic in the same order, so both give bit-identical trajectories
(``tests/impact_env/tether/test_fast_path.py``). The attributes below are set by ``TetherWorld.__init__``.
"""

from __future__ import annotations

import math
from typing import Any

import pymunk

from impact_env.errors import TetherError
from impact_env.tether.station import Station

try:  # the C functions behind pymunk's properties, for the hot loop (see TetherWorld.step)
    from pymunk._chipmunk import lib as chipmunk_lib
except ImportError:  # pragma: no cover - a pymunk build without the cffi module: public API only
    chipmunk_lib = None

SLOP_M = 1e-4  # pymunk's collision slop in the tether world (m)
CHECK_MARGIN_M = 1e-9  # the stop-radius and sight budgets end this much early (rounding of the exact tests)


class Tether:
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


class SubstepBase:
    """The state a substep reads and writes, and the pymunk calls every fidelity's loop makes."""

    station: Station
    space: pymunk.Space
    cargo: pymunk.Body
    dt_s: float
    substeps: int
    n_substeps_done: int
    winch_work_J: float
    _winch_N: float
    _stop: float  # the stop radius (m)
    _stop2: float
    _anchors: tuple[tuple[float, float], ...]
    _wall_a: Any  # the walls' start points, edges and squared lengths (numpy arrays, Station.wall_arrays)
    _wall_e: Any
    _wall_ee: Any
    _notches: Any
    _notch_rays: dict[int, list[tuple[float, float, float, float]] | None]
    _cache: bool
    _wall_seen_at: tuple[float, float]
    _wall_margin: float
    _tethers: list[Tether | None]
    _active: list[Tether] | None  # the pulling tethers in robot order; None: to be rebuilt
    _next_ready: float  # the earliest ready time of an attaching tether
    _budget: float  # how far the cargo may move from _checked_at before a tether check can change anything
    _checked_at: tuple[float, float]
    _fast: bool
    _body_ptr: Any  # chipmunk's pointers to the cargo and the space (the fast path)
    _space_ptr: Any
    _kinematic_loop: Any  # the compiled kinematic loop (impact_env.tether.native), or None
    _planned: list[Tether] | None  # the active list the compiled loop's plan was made from

    @property
    def time_s(self) -> float:
        return self.n_substeps_done * self.dt_s

    def state(self) -> tuple[float, float, float, float]:
        """(x, y, vx, vy) of the cargo (m, m/s)."""
        if self._fast:
            p, v = chipmunk_lib.cpBodyGetPosition(self._body_ptr), chipmunk_lib.cpBodyGetVelocity(self._body_ptr)
        else:
            p, v = self.cargo.position, self.cargo.velocity
        return (p.x, p.y, v.x, v.y)

    def release(self, robot: int, kind: str = "released") -> None:
        raise NotImplementedError  # TetherWorld's

    def _activate_ready(self) -> None:
        raise NotImplementedError  # TetherWorld's

    def _check_tethers(self, active: list[Tether]) -> None:
        raise NotImplementedError  # impact_env.tether.checks

    def _begin_fast(self) -> tuple:
        if self._active is None:
            self._active = [t for t in self._tethers if t is not None and t.pulling]
            self._budget = -1.0
        p, v = chipmunk_lib.cpBodyGetPosition(self._body_ptr), chipmunk_lib.cpBodyGetVelocity(self._body_ptr)
        return p.x, p.y, v.x, v.y

    def _after_substep_fast(self, active: list[Tether], x: float, y: float) -> None:
        """The tether checks and the attachments that become ready after a physics step, cargo at (x, y)."""
        if active:
            cx, cy = self._checked_at
            if not math.hypot(x - cx, y - cy) < self._budget:
                self._check_tethers(active)
        if self._next_ready <= self.n_substeps_done * self.dt_s + 1e-9:
            self._activate_ready()

    def _space_step(self, dt: float) -> None:
        if self._fast:
            space = self.space
            space._locked = True  # as pymunk's own step(): callbacks may not add or remove shapes
            try:
                chipmunk_lib.cpSpaceStep(self._space_ptr, dt)
            finally:
                space._locked = False
        else:
            self.space.step(dt)

    def _velocity_after(self) -> tuple[float, float]:
        v = chipmunk_lib.cpBodyGetVelocity(self._body_ptr) if self._fast else self.cargo.velocity
        return v.x, v.y

    def _set_max(self, t: Tether, length: float) -> None:
        if self._fast:
            chipmunk_lib.cpSlideJointSetMax(t.jptr, length)
        else:
            t.slide_joint().max = length
