"""The pymunk world of a scenario: frictionless discs in microgravity, exact restitution, impact log.

No gravity and no damping (pymunk's ``space.damping = 1.0`` is full velocity retention); robots and objects
are dynamic bodies and robots are driven by forces only (a kinematic robot has infinite mass and would double
the impulse it gives an object); every shape gets ``sqrt(e)``, so every pair bounces with exactly the
scenario's ``e`` (pymunk multiplies the two elasticities); the collision slop is 0.1 mm. Every contact is
logged as an :class:`ImpactEvent` from first touch to separation, its impulse summed over the substeps it
lasts, and the contacts that end in one substep are closed after it in the scenario's order of the shapes
(chipmunk's own order depends on where malloc put them: ``docs/background.md#physics``). Optional post-impact
velocity noise perturbs an object when a robot-object contact ends: the error the impact-robust planner's delta
bounds. Three paths drive the substeps, all bit-identical (``tests/impact_env/transport/test_physics.py``,
``tests/impact_env/transport/test_native_parity.py``): the compiled loop (:mod:`impact_env.transport.native`, one
call per control period), chipmunk's C functions called from Python where that loop is not built, and pymunk's
public API (``fast=False``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pymunk

from impact_env.transport import native
from impact_env.transport.scenario import Scenario

try:  # the C functions behind pymunk's properties, for the hot loop (see World.step)
    from pymunk._chipmunk import lib as _cp
except ImportError:  # pragma: no cover - a pymunk build without the cffi module: public API only
    _cp = None

WALL = "wall"  # name of the world boundary in impact events
_SLOP_M = 1e-4
_WALL_THICKNESS_M = 1.0


@dataclass
class ImpactEvent:
    """One contact between two bodies (or a body and a wall/obstacle), from first touch to separation.

    ``a``/``b`` are body or obstacle names; velocities are the bodies' linear velocities (m/s) at first
    touch and at separation; ``impulse_Ns`` is the magnitude of the impulse summed over the contact.
    """

    time_s: float
    a: str
    b: str
    impulse_Ns: float
    a_velocity_before: tuple[float, float]
    b_velocity_before: tuple[float, float]
    a_velocity_after: tuple[float, float]
    b_velocity_after: tuple[float, float]
    duration_s: float = 0.0

    def velocity_before(self, name: str) -> tuple[float, float]:
        """Velocity (m/s) of body ``name`` (``a`` or ``b``) at first touch."""
        return self._pick(name, self.a_velocity_before, self.b_velocity_before)

    def velocity_after(self, name: str) -> tuple[float, float]:
        """Velocity (m/s) of body ``name`` (``a`` or ``b``) at separation."""
        return self._pick(name, self.a_velocity_after, self.b_velocity_after)

    def _pick(self, name: str, va: tuple[float, float], vb: tuple[float, float]) -> tuple[float, float]:
        if name == self.a:
            return va
        if name == self.b:
            return vb
        raise KeyError(f"impact between {self.a!r} and {self.b!r} does not involve {name!r}")

    def to_dict(self) -> dict[str, Any]:
        return {
            "time": self.time_s, "a": self.a, "b": self.b, "impulse": self.impulse_Ns,
            "a_velocity_before": list(self.a_velocity_before), "b_velocity_before": list(self.b_velocity_before),
            "a_velocity_after": list(self.a_velocity_after), "b_velocity_after": list(self.b_velocity_after),
            "duration": self.duration_s,
        }


class _Contact:
    __slots__ = ("time_s", "a", "b", "body_a", "body_b", "va", "vb", "jx", "jy", "rank", "end_s", "va_end",
                 "vb_end")
    time_s: float  # when the contact began (s)
    a: str
    b: str
    body_a: pymunk.Body
    body_b: pymunk.Body
    va: tuple[float, float]  # velocities before (m/s)
    vb: tuple[float, float]
    jx: float  # the impulse summed over the contact's substeps (N s)
    jy: float
    rank: tuple[int, int]
    end_s: float  # when it ended (s), and the velocities then
    va_end: tuple[float, float]
    vb_end: tuple[float, float]


def _xy(v: pymunk.Vec2d) -> tuple[float, float]:
    return v.x, v.y


# Module-level callbacks (lambdas would stop a World from being pickled).
def _on_begin(arbiter: pymunk.Arbiter, space: pymunk.Space, world: World) -> None:
    sa, sb = arbiter.shapes
    body_a, body_b = sa.body, sb.body
    if body_a is None or body_b is None:  # pymunk types a shape's body as optional; every shape here has one
        return
    c = _Contact()
    c.time_s = world.time_s
    c.a, c.b = world._shape_names[sa], world._shape_names[sb]
    c.body_a, c.body_b = body_a, body_b
    c.va, c.vb = _xy(body_a.velocity), _xy(body_b.velocity)
    c.jx = c.jy = 0.0
    ra, rb = world._shape_rank[sa], world._shape_rank[sb]
    c.rank = (ra, rb) if ra <= rb else (rb, ra)  # the pair's place in the fixed order of closing
    world._open[(sa, sb)] = c


def _on_post_solve(arbiter: pymunk.Arbiter, space: pymunk.Space, world: World) -> None:
    c = world._open.get(arbiter.shapes)
    if c is not None:
        j = arbiter.total_impulse
        c.jx += j.x
        c.jy += j.y


def _on_separate(arbiter: pymunk.Arbiter, space: pymunk.Space, world: World) -> None:
    # only noted here: chipmunk calls this in the order of its address-keyed hash set (see the module), so the
    # contact is closed in World._close_separated, in the fixed order, once the substep is over
    c = world._open.pop(arbiter.shapes, None)
    if c is not None:
        c.end_s = world.time_s
        c.va_end, c.vb_end = _xy(c.body_a.velocity), _xy(c.body_b.velocity)
        world._separated.append(c)


def _close(c: _Contact, time_s: float, va_end: tuple[float, float] | None = None,
           vb_end: tuple[float, float] | None = None) -> ImpactEvent:
    return ImpactEvent(
        time_s=c.time_s, a=c.a, b=c.b, impulse_Ns=math.hypot(c.jx, c.jy),
        a_velocity_before=c.va, b_velocity_before=c.vb,
        a_velocity_after=_xy(c.body_a.velocity) if va_end is None else va_end,
        b_velocity_after=_xy(c.body_b.velocity) if vb_end is None else vb_end,
        duration_s=time_s - c.time_s,
    )


class World:
    """A fresh pymunk space for one episode of a scenario.

    Args:
        scenario: the scenario to build.
        restitution: override of the scenario's restitution (model-mismatch studies); default the scenario's.
        initial_positions_m: optional name -> (x, y) overriding bodies' initial positions.
        fast: run the substeps in the compiled loop, or where it is not built through chipmunk's C functions
            from Python (same results, faster); False: pymunk's public API.
        impact_velocity_noise_mps: when a robot-object contact ends, add a uniform error in [-this, this]
            (m/s) on each axis to the object's velocity, drawn from ``rng`` (required when > 0).
        rng: the random generator of the noise (the environment passes its reset-seeded generator).

    Bodies are ordered as ``scenario.bodies`` (robots, then objects). Robot inputs are body-frame forces
    (N) and torques (N m), held constant over a control period of ``scenario.substeps`` physics steps: the
    argument of :meth:`step`, or what the caller wrote into :attr:`wrench` ((n_robots, 3) float64).
    """

    def __init__(self, scenario: Scenario, restitution: float | None = None,
                 initial_positions_m: Mapping[str, tuple[float, float]] | None = None, fast: bool = True,
                 impact_velocity_noise_mps: float = 0.0, rng: Any = None) -> None:
        if not (math.isfinite(impact_velocity_noise_mps) and impact_velocity_noise_mps >= 0.0):
            raise ValueError(f"impact_velocity_noise_mps must be a finite number >= 0, got {impact_velocity_noise_mps}")
        if impact_velocity_noise_mps > 0.0 and rng is None:
            raise ValueError("impact_velocity_noise_mps > 0 needs rng, a numpy random Generator")
        self.impact_velocity_noise_mps = float(impact_velocity_noise_mps)
        self._rng = rng
        self._robot_names = {r.name for r in scenario.robots}
        self._object_names = {o.name for o in scenario.objects}
        self.scenario = scenario
        self.restitution = scenario.restitution if restitution is None else float(restitution)
        self.dt_s = scenario.physics_dt_s
        self.substeps = scenario.substeps
        self._n_substeps_done = 0
        self._open: dict[tuple[pymunk.Shape, pymunk.Shape], _Contact] = {}
        self._separated: list[_Contact] = []  # contacts that ended in the current substep, not yet closed
        self._closed: list[ImpactEvent] = []
        self._shape_names: dict[pymunk.Shape, str] = {}

        space = pymunk.Space()
        space.gravity = (0.0, 0.0)
        space.damping = 1.0
        space.collision_slop = _SLOP_M
        self.space = space
        elasticity = math.sqrt(self.restitution)
        overrides = dict(initial_positions_m or {})

        self.bodies: list[pymunk.Body] = []
        for spec in scenario.bodies:
            body = pymunk.Body(spec.mass_kg, spec.inertia_kgm2, body_type=pymunk.Body.DYNAMIC)
            body.position = overrides.pop(spec.name, spec.position_m)
            body.velocity = spec.velocity_mps
            body.angle = spec.heading_rad
            body.angular_velocity = spec.angular_velocity_radps
            shape = pymunk.Circle(body, spec.radius_m)
            self._add_shape(shape, spec.name, elasticity)
            space.add(body, shape)
            self.bodies.append(body)
        if overrides:
            raise KeyError(f"initial_positions_m names unknown bodies: {sorted(overrides)}")
        self.robots = self.bodies[: len(scenario.robots)]

        static = space.static_body
        xmin, xmax, ymin, ymax = scenario.world_box
        w = _WALL_THICKNESS_M
        for box in ((xmin - w, xmax + w, ymin - w, ymin), (xmin - w, xmax + w, ymax, ymax + w),
                    (xmin - w, xmin, ymin, ymax), (xmax, xmax + w, ymin, ymax)):
            x0, x1, y0, y1 = box
            self._add_shape(pymunk.Poly(static, [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]), WALL, elasticity)
        for obstacle in scenario.obstacles:
            self._add_shape(pymunk.Poly(static, [tuple(v) for v in obstacle.polygon.vertices]), obstacle.name,
                            elasticity)
        space.add(*[s for s in self._shape_names if s.body is static])
        self._shape_rank = {s: k for k, s in enumerate(self._shape_names)}  # bodies in scenario order, walls, obstacles
        space.on_collision(None, None, begin=_on_begin, post_solve=_on_post_solve, separate=_on_separate, data=self)
        self.wrench = np.zeros((len(self.robots), 3))  # body-frame (Fx, Fy, torque) per robot, N and N m
        # the robots' (Fx, Fy, torque) limits: what the compiled loop's set_action scales a normalised action by
        self.wrench_limits = np.array([r.wrench_limits for r in scenario.robots], dtype=float)
        self._fast: tuple[Any, list[Any]] | None = None  # chipmunk's space and robot bodies (C pointers)
        if _cp is not None and fast:
            try:
                self._fast = (space._space, [b._body for b in self.robots])
                self._all_ptrs = [b._body for b in self.bodies]
            except AttributeError:  # pragma: no cover - pymunk internals moved: use the public API
                self._fast = None
        self._loop = None if self._fast is None else native.substep_loop(
            space, self.bodies, len(self.robots), self.dt_s, self._separated, self.wrench, self.wrench_limits)

    def _add_shape(self, shape: pymunk.Shape, name: str, elasticity: float) -> None:
        shape.elasticity = elasticity
        shape.friction = 0.0
        self._shape_names[shape] = name

    @property
    def n_substeps_done(self) -> int:
        """Physics substeps taken since the world was built."""
        return self._n_substeps_done if self._loop is None else self._loop.substeps_done

    @n_substeps_done.setter
    def n_substeps_done(self, value: int) -> None:
        if self._loop is None:
            self._n_substeps_done = value
        else:
            self._loop.substeps_done = value

    @property
    def time_s(self) -> float:
        return self.n_substeps_done * self.dt_s

    def _close_separated(self) -> None:
        """Close the contacts that ended in the substep just taken, in the fixed order of their shapes: each
        robot-object one first gets its post-impact velocity error (see the class), then is logged.

        The error is added to the object's velocity now, after the substep, rather than inside chipmunk's
        separate callback: an object with no other contact is neither pushed nor accelerated in that substep,
        so its velocity and its next positions are the same bit for bit; only an object that leaves one
        contact while it is in another in the same substep sees its other contact solved without the error.
        """
        separated = sorted(self._separated, key=lambda c: c.rank)
        self._separated.clear()
        for c in separated:
            va, vb = c.va_end, c.vb_end
            if self.impact_velocity_noise_mps > 0.0:
                if c.a in self._robot_names and c.b in self._object_names:
                    vb = self._perturb_object(c.body_b, vb)
                elif c.b in self._robot_names and c.a in self._object_names:
                    va = self._perturb_object(c.body_a, va)
            self._closed.append(_close(c, c.end_s, va, vb))

    def _perturb_object(self, body: pymunk.Body, v_end: tuple[float, float]) -> tuple[float, float]:
        """Add the uniform error to the object's velocity; return its separation velocity with the error."""
        noise = self.impact_velocity_noise_mps
        ex, ey = (float(e) for e in self._rng.uniform(-noise, noise, 2))
        v = body.velocity
        body.velocity = (v.x + ex, v.y + ey)
        return v_end[0] + ex, v_end[1] + ey

    def step(self, wrenches: Sequence[tuple[float, float, float]] | None = None) -> list[ImpactEvent]:
        """Advance one control period with each robot's body-frame (Fx, Fy, torque) held constant: ``wrenches``,
        or (None) the values in :attr:`wrench`.

        The wrenches must already respect the thrust limits (the environments clip them). Returns the
        impact events that ended (separated) during this period.
        """
        if wrenches is not None:
            self.wrench[...] = wrenches
        if self._loop is not None:
            return self._step_compiled(self._loop)
        held = [(fx, fy, tau) for fx, fy, tau in self.wrench.tolist()]
        if self._fast is not None:
            return self._step_fast(self._fast, held)
        robots = self.robots
        space_step = self.space.step
        dt = self.dt_s
        for _ in range(self.substeps):
            for body, (fx, fy, tau) in zip(robots, held):
                c, s = math.cos(body.angle), math.sin(body.angle)
                body.force = (c * fx - s * fy, s * fx + c * fy)
                body.torque = tau
            space_step(dt)
            self.n_substeps_done += 1
            if self._separated:
                self._close_separated()
        closed, self._closed = self._closed, []
        return closed

    def _step_compiled(self, loop: Any) -> list[ImpactEvent]:
        """The substeps in C (``loop``: :mod:`impact_env.transport.native`'s); each contact that ends is closed
        here, after its substep and before the next, as on the other paths."""
        space = self.space
        left = self.substeps
        while left:
            space._locked = True  # as pymunk's own step(): callbacks may not add or remove shapes
            try:
                left -= loop.run(left)
            finally:
                space._locked = False
            if self._separated:
                self._close_separated()
        closed, self._closed = self._closed, []
        return closed

    def _step_fast(self, fast: tuple[Any, list[Any]],
                   wrenches: Sequence[tuple[float, float, float]]) -> list[ImpactEvent]:
        space_ptr, body_ptrs = fast
        cp, cos, sin = _cp, math.cos, math.sin
        dt = self.dt_s
        pairs = list(zip(body_ptrs, wrenches))
        for _ in range(self.substeps):
            for ptr, (fx, fy, tau) in pairs:
                a = cp.cpBodyGetAngle(ptr)
                c, s = cos(a), sin(a)
                cp.cpBodySetForce(ptr, (c * fx - s * fy, s * fx + c * fy))
                cp.cpBodySetTorque(ptr, tau)
            self.space._locked = True  # as pymunk's own step(): callbacks may not add or remove shapes
            try:
                cp.cpSpaceStep(space_ptr, dt)
            finally:
                self.space._locked = False
            self.n_substeps_done += 1
            if self._separated:
                self._close_separated()
        closed, self._closed = self._closed, []
        return closed

    def flush_impacts(self) -> list[ImpactEvent]:
        """Close the contacts still open (end of episode): their 'after' velocities are the current ones."""
        contacts = sorted(self._open.values(), key=lambda c: (c.time_s, c.rank))
        self._open.clear()
        return [_close(c, self.time_s) for c in contacts]

    def read_state(self) -> list[tuple[float, float, float, float, float, float]]:
        """Per body (x, y, vx, vy, heading, angular velocity) in SI units, scenario body order."""
        out: list[tuple[float, float, float, float, float, float]] = []
        if self._loop is not None:
            rows = np.empty((len(self.bodies), 6))
            self._loop.read_state(rows)
            return [(x, y, vx, vy, th, om) for x, y, vx, vy, th, om in rows.tolist()]
        if self._fast is not None:
            cp = _cp
            for ptr in self._all_ptrs:
                p, v = cp.cpBodyGetPosition(ptr), cp.cpBodyGetVelocity(ptr)
                out.append((p.x, p.y, v.x, v.y, cp.cpBodyGetAngle(ptr), cp.cpBodyGetAngularVelocity(ptr)))
            return out
        for b in self.bodies:
            p, v = b.position, b.velocity
            out.append((p.x, p.y, v.x, v.y, b.angle, b.angular_velocity))
        return out

    def read_state_into(self, out: np.ndarray) -> None:
        """:meth:`read_state` written into ``out``, a C-contiguous (n_bodies, 6) float64 array."""
        if self._loop is not None:
            self._loop.read_state(out)
        else:
            out[...] = self.read_state()
