"""What the simulator needs of a scenario: the physical and numerical limits checked on load.

pymunk integrates with a fixed step and detects contacts between positions, so a body that moves too far
in one substep can pass through a disc or a wall, and a body whose mass or yaw inertia is tiny gets an
infinite inverse (then NaN). The scenario loader calls these checks so that such a scenario is a
:class:`~impact_env.errors.ScenarioError` naming the field, not a body outside the world later: impacts
accurate to a quarter radius per substep, no tunnelling at the fastest reachable speed, at most
:data:`MAX_SUBSTEPS` substeps and :data:`MAX_EPISODE_STEPS` steps, masses and inertias in range, a bounded
yaw rate. Why each limit is where it is: ``docs/background.md#limits`` (``docs/scenario_format.md`` repeats
them for users).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from impact_env.errors import ScenarioError

MAX_SUBSTEPS = 1000
MAX_EPISODE_STEPS = 10_000_000
MAX_TF_S = 1e6
MIN_MASS_KG = 1e-6
MAX_MASS_KG = 1e9
MIN_INERTIA_FRACTION = 1e-6
MAX_YAW_RATE_RADPS = 1e4
ACCURACY_FRACTION = 0.25  # of the smallest radius, per substep, at planned speeds
TUNNELLING_FRACTION = 1.0  # of the smallest radius, per substep, at reachable speeds


def check_timing(tf_s: float, control_period_s: float, substeps: int) -> None:
    """tf_s, control period and substeps within what one episode can run."""
    if tf_s > MAX_TF_S:
        raise ScenarioError(f"tf_s must be <= {MAX_TF_S:g} s, got {tf_s:g}")
    if substeps > MAX_SUBSTEPS:
        raise ScenarioError(f"substeps must be <= {MAX_SUBSTEPS} per control period (each env step would run "
                            f"{substeps} physics steps), got {substeps}")
    if tf_s / control_period_s > MAX_EPISODE_STEPS:
        raise ScenarioError(f"tf_s / control_period_s = {tf_s / control_period_s:.3g} control periods; at most "
                            f"{MAX_EPISODE_STEPS:,} are allowed: raise control_period_s or lower tf_s")


def check_body(body: Any, where: str, tf_s: float) -> None:
    """Mass, inertia and reachable yaw rate of one body (a :class:`impact_env.transport.scenario.Body`)."""
    if not MIN_MASS_KG <= body.mass_kg <= MAX_MASS_KG:
        raise ScenarioError(f"{where}.mass_kg must be in [{MIN_MASS_KG:g}, {MAX_MASS_KG:g}] kg, got {body.mass_kg:g}")
    rim = body.mass_kg * body.radius_m * body.radius_m
    if body.inertia_kgm2 < MIN_INERTIA_FRACTION * rim:
        raise ScenarioError(f"{where}.inertia_kgm2 = {body.inertia_kgm2:g} is below {MIN_INERTIA_FRACTION:g} m r^2 = "
                            f"{MIN_INERTIA_FRACTION * rim:.3g} kg m^2; a uniform disc of this mass and radius has "
                            f"m r^2 / 2 = {rim / 2:.4g} kg m^2")
    spin = abs(body.angular_velocity_radps)
    if body.is_robot:
        spin += body.torque_limit_Nm / body.inertia_kgm2 * tf_s
    if not spin <= MAX_YAW_RATE_RADPS:
        cause = ("torque_limit_Nm / inertia_kgm2 over tf_s" if body.is_robot else "angular_velocity_radps")
        raise ScenarioError(f"{where}: {cause} lets the body spin at {spin:.3g} rad/s; at most "
                            f"{MAX_YAW_RATE_RADPS:g} rad/s are supported (raise inertia_kgm2 or lower the torque "
                            "limit or initial yaw rate)")


def fastest_speed(bodies: Sequence[Any], kinds: Sequence[str], restitution: float,
                  world_box: tuple[float, float, float, float], thrust: bool) -> tuple[float, str]:
    """(1 + e) times the fastest planned (``thrust=False``) or reachable (``thrust=True``) speed (m/s), and
    the field that sets it; see the module docstring."""
    diagonal = math.hypot(world_box[1] - world_box[0], world_box[3] - world_box[2])
    best, cause = 0.0, ""
    for body, where in zip(bodies, kinds):
        v0 = math.hypot(*body.velocity_mps)
        candidates = [(v0, f"{where}.velocity_mps")]
        if body.velocity_bound_mps is not None:
            candidates.append((math.hypot(*body.velocity_bound_mps), f"{where}.velocity_bound_mps"))
        if thrust and body.is_robot:
            accel = math.hypot(*body.thrust_limit_N) / body.mass_kg
            candidates.append((math.sqrt(v0 * v0 + 2.0 * accel * diagonal),
                               f"{where}.thrust_limit_N (a full-thrust run across the world)"))
        for speed, label in candidates:
            if not speed <= best:  # inf and NaN win, so they are reported
                best, cause = speed, label
    return (1.0 + restitution) * best, cause


def check_tunnelling(bodies: Sequence[Any], kinds: Sequence[str], restitution: float,
                     world_box: tuple[float, float, float, float], control_period_s: float, substeps: int) -> None:
    """Planned speeds move a body < r_min / 4 per substep, reachable ones < r_min (see the module docstring)."""
    if not bodies:
        return
    r_min = min(b.radius_m for b in bodies)
    dt = control_period_s / substeps
    for thrust, fraction, what in ((False, ACCURACY_FRACTION, "a quarter of"), (True, TUNNELLING_FRACTION, "")):
        v_max, cause = fastest_speed(bodies, kinds, restitution, world_box, thrust)
        step = fraction * r_min
        if v_max * dt <= step:
            continue
        need_f = v_max * control_period_s / step if step > 0 else math.inf  # a radius of 5e-324 m gives 0
        need = math.ceil(need_f) if need_f < 1e15 else math.inf
        moved = (f"at {v_max:.3g} m/s (1 + e times the speed set by {cause}) a body moves {v_max * dt:.3g} m per "
                 f"substep, more than {what + ' ' if what else ''}the smallest radius ({r_min:g} m)")
        if need <= MAX_SUBSTEPS:
            raise ScenarioError(f"substeps = {substeps} is too few: {moved}; use substeps >= {need}")
        raise ScenarioError(f"{moved}; even the maximum of {MAX_SUBSTEPS} substeps is too few (it would need "
                            f"{need:.3g}): lower the speed set by {cause.split(' ')[0]}, raise the radii or shorten "
                            "control_period_s")
