"""Test-only harness: fly a plan open-loop in the pymunk world with the robots following it exactly.

Each substep sets every robot's velocity so that it lands on its planned position at the end of the
substep. The planner treats bodies as points (Assumption 1), so around each planned impact the robot's
path is shifted back by the sum of the radii along the impact normal (the direction of the object's
velocity change), which puts the discs in contact exactly at the planned impact time (the two-body
contact point of docs/background.md#planner, item 5). The shift is blended in over the first half of the
pre-impact interval and out after the post-impact interval, so the robot's velocity at the impact is the
planned one.

A point-mass plan does not keep robots' discs off objects' discs between impacts (the controller does
that, issue 4, e.g. when a robot overtakes the object it has just hit); the harness stands in for a
robot that follows the plan exactly and so lets robot-object contacts through only within a quarter grid
interval of a planned impact of that pair.
"""

from __future__ import annotations

import math

import numpy as np

from impact_env.stl import robustness
from impact_env.transport.physics import World
from impact_env.transport.scenario import Scenario
from planners.plan import Plan


def _smoothstep(u: float) -> float:
    u = min(1.0, max(0.0, u))
    return u * u * (3.0 - 2.0 * u)


def contact_offsets(plan: Plan, scenario: Scenario, window_s: float, substep_s: float):
    """robot name -> function t -> (dx, dy) shift of the planned path.

    The shift is the sum of the radii less half a substep of approach, so that pymunk (which detects
    contacts at the end of a substep) sees the discs overlap in the substep that ends at the impact time,
    while the robot still has its pre-impact velocity.
    """
    per_robot: dict[str, list[tuple[float, np.ndarray]]] = {}
    for imp in plan.impacts:
        dv = np.subtract(imp.object_velocity_after, imp.object_velocity_before)
        if np.linalg.norm(dv) < 1e-9:
            continue
        n = dv / np.linalg.norm(dv)
        approach = float(np.dot(np.subtract(imp.robot_velocity_before, imp.object_velocity_before), n))
        gap = scenario.body(imp.robot).radius_m + scenario.body(imp.object).radius_m - 0.5 * approach * substep_s
        per_robot.setdefault(imp.robot, []).append((imp.time_s, -gap * n))

    def make(events):
        def offset(t: float) -> np.ndarray:
            best_w, best = 0.0, np.zeros(2)
            for t_i, off in events:
                # in over the first half of the pre-impact interval, out over the half interval after
                # the post-impact one (when robot-object contacts are no longer let through)
                if t <= t_i:
                    u = (t - (t_i - window_s)) / (0.5 * window_s)
                else:
                    u = ((t_i + 1.5 * window_s) - t) / (0.5 * window_s)
                w = _smoothstep(u)
                if w > best_w:
                    best_w, best = w, off
            return best_w * best
        return offset

    return {name: make(events) for name, events in per_robot.items()}


def _allow_planned_contacts_only(world: World, plan: Plan, window_s: float) -> None:
    from impact_env.transport import physics

    robots = {r.name for r in world.scenario.robots}
    objects = {o.name for o in world.scenario.objects}
    windows: dict[frozenset, list[tuple[float, float]]] = {}
    for imp in plan.impacts:
        windows.setdefault(frozenset((imp.robot, imp.object)), []).append((imp.time_s - window_s,
                                                                          imp.time_s + window_s))

    def begin(arbiter, space, data):
        a, b = (world._shape_names[s] for s in arbiter.shapes)
        if {a, b} & robots and {a, b} & objects:
            if not any(lo <= world.time_s <= hi for lo, hi in windows.get(frozenset((a, b)), [])):
                arbiter.process_collision = False
                return
        physics._on_begin(arbiter, space, world)

    world.space.on_collision(None, None, begin=begin, post_solve=physics._on_post_solve,
                             separate=physics._on_separate, data=world)


def replay(plan: Plan, scenario: Scenario) -> tuple[dict[str, np.ndarray], float, list]:
    """Simulate the plan; return (trace sampled every control period, its robustness, impact events)."""
    world = World(scenario)
    window = min(s.duration_s for b in plan.bodies.values() for s in b.segments)
    offsets = contact_offsets(plan, scenario, window, world.dt_s)
    _allow_planned_contacts_only(world, plan, 0.25 * window)
    robots = list(zip(scenario.robots, world.robots))
    dt = world.dt_s
    steps = round(scenario.formula.horizon_s / scenario.control_period_s)
    names = [b.name for b in scenario.bodies]
    trace = {n: [tuple(b.position)] for n, b in zip(names, world.bodies)}
    events = []
    for _ in range(steps):
        for _ in range(world.substeps):
            t_next = world.time_s + dt
            for spec, body in robots:
                target = plan.position(spec.name, t_next)
                if spec.name in offsets:
                    target = target + offsets[spec.name](t_next)
                body.velocity = tuple((target - np.array(body.position)) / dt)
                body.angular_velocity = 0.0
            world.space.step(dt)
            world.n_substeps_done += 1
            world._close_separated()  # as World.step does after each substep
        events += world._closed
        world._closed = []
        for n, b in zip(names, world.bodies):
            trace[n].append(tuple(b.position))
    arrays = {n: np.array(v) for n, v in trace.items()}
    rho = robustness(scenario.formula, arrays, scenario.region_map(), scenario.control_period_s)
    return arrays, rho, events + world.flush_impacts()


def speed(v) -> float:
    return math.hypot(*v)
