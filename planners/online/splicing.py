"""Plan surgery for the mission layer's re-plans: a plan resampled onto a new grid (the warm start), the
executed part of a plan followed by a re-planned remainder, and the derived scenario's bodies.

:func:`splice` keeps the executed part's curves up to the re-plan time and appends the remainder shifted to
absolute time, with an impact-robust remainder's funnels and robot copies shifted with it; the impacts in the
past count as done. :func:`initial_state` puts an observed state into a body (inside the planner's box, with a
velocity bound no smaller than its speed), :func:`without_end_states` drops every body's end state (the
re-plan's second try). Used by :mod:`planners.online.mission` and :mod:`planners.online.station_keeping`.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from impact_env.transport.scenario import Body, Scenario
from planners import bezier
from planners.online.sampling import PlanSampler
from planners.plan import BodyPlan, Plan, Segment


def resample_plan(plan: Plan, t0: float, tf: float, intervals: int, degree: int) -> Plan:
    """The plan's motion on [t0, tf] expressed on a new grid of ``intervals`` equal intervals (time 0 = t0):
    robots as degree-``degree`` Bezier segments (least-squares fit of the old curve), objects as straight
    segments between their old positions at the new knots, impacts moved to the nearest new knot. A warm
    start for the planner, not a flyable plan."""
    sampler = PlanSampler(plan)
    knots = np.linspace(t0, tf, intervals + 1)
    m = 3 * (degree + 1)
    phases = np.linspace(0.0, 1.0, m)
    fit = np.linalg.pinv(bezier.bernstein(degree, phases))  # (d+1, m)
    bodies = {}
    for name, body in plan.bodies.items():
        segments = []
        for a, b in zip(knots[:-1], knots[1:]):
            if body.kind == "robot":
                pts = sampler.state(name, a + phases * (b - a))[:, :2]
                cp = fit @ pts
            else:
                cp = sampler.state(name, np.array([a, b]))[:, :2]
            segments.append(Segment(a - t0, b - t0, cp))
        bodies[name] = BodyPlan(name, body.kind, segments)
    dt = (tf - t0) / intervals
    impacts = [dataclasses.replace(i, time_s=round((i.time_s - t0) / dt) * dt) for i in plan.impacts
               if t0 < i.time_s <= tf and 1 <= round((i.time_s - t0) / dt) <= intervals]
    return Plan(plan.scenario, plan.planner, plan.robustness, bodies, impacts)


def _clip_segment(seg: Segment, t: float) -> Segment | None:
    """The part of ``seg`` before time ``t`` (None if none)."""
    if t <= seg.t0_s + 1e-12:
        return None
    if t >= seg.t1_s:
        return seg
    left, _ = bezier.split(seg.control_points, (t - seg.t0_s) / seg.duration_s)
    return Segment(seg.t0_s, t, left)


def splice(executed: Plan, remainder: Plan, t: float) -> tuple[Plan, set[int]]:
    """``executed`` on [0, t] followed by ``remainder`` (planned from time 0 = t) shifted to absolute time.

    Returns the spliced plan and the indices of its impacts that lie in the past (they count as done: the
    ones that happened were observed, the ones that did not will not be flown any more)."""
    bodies = {}
    for name, body in executed.bodies.items():
        past = [s for s in (_clip_segment(seg, t) for seg in body.segments) if s is not None]
        future = [Segment(s.t0_s + t, s.t1_s + t, np.asarray(s.control_points, float).copy())
                  for s in remainder.bodies[name].segments]
        bodies[name] = BodyPlan(name, body.kind, past + future)
    old = [i for i in executed.impacts if i.time_s <= t + 1e-9]
    new = [dataclasses.replace(i, time_s=i.time_s + t) for i in remainder.impacts]
    # an impact-robust remainder keeps its funnels and robot copies, shifted with it (the executed part's
    # copies belong to impacts that are done)
    funnels = {name: dataclasses.replace(f, t0_s=f.t0_s + t) for name, f in remainder.funnels.items()}
    copies = [dataclasses.replace(c, time_s=c.time_s + t, window_start_s=c.window_start_s + t,
                                  window_end_s=c.window_end_s + t) for c in remainder.copies]
    spliced = Plan(executed.scenario, remainder.planner, remainder.robustness, bodies, old + new,
                   remainder.solver, remainder.solve_time_s, remainder.build_time_s, remainder.mip_gap,
                   {**remainder.stats, "spliced_at_s": t}, remainder.delta_mps, funnels, copies)
    return spliced, set(range(len(old)))


def initial_state(body: Body, position: np.ndarray, velocity: np.ndarray, scenario: Scenario) -> Body:
    """The body with the observed state as its initial state, nudged inside the planner's allowed box and
    with a velocity bound no smaller than its observed speed (else the derived problem starts infeasible)."""
    xmin, xmax, ymin, ymax = scenario.world_box
    x0, x1, y0, y1 = xmin + body.radius_m, xmax - body.radius_m, ymin + body.radius_m, ymax - body.radius_m
    eps = 1e-6  # the planner's box for a centre (the world shrunk by the radius), strictly inside
    p = (float(np.clip(position[0], x0 + eps, x1 - eps)), float(np.clip(position[1], y0 + eps, y1 - eps)))
    v = (float(velocity[0]), float(velocity[1]))
    bound = body.velocity_bound_mps
    if bound is not None:
        bound = (max(bound[0], abs(v[0]) * 1.01), max(bound[1], abs(v[1]) * 1.01))
    return dataclasses.replace(body, position_m=p, velocity_mps=v, velocity_bound_mps=bound)


def without_end_states(scenario: Scenario) -> Scenario:
    """The scenario with no final position or velocity for any body (only the task is left)."""
    def free(body: Body) -> Body:
        return dataclasses.replace(body, final_position_m=None, final_velocity_mps=None)

    return dataclasses.replace(scenario, robots=tuple(free(b) for b in scenario.robots),
                               objects=tuple(free(b) for b in scenario.objects))


__all__ = ["initial_state", "resample_plan", "splice", "without_end_states"]
