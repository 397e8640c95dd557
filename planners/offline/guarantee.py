"""What an impact-robust plan promises, flown by point masses: a check that does not trust the planner.

:func:`rollout` flies the plan's point-mass model (the planner's Assumption 1-2) when impact i sends the
object off with a velocity error ``errors[i]`` (m/s per axis, on top of the point-mass law): between
impacts objects fly straight; at each impact the impacting robot flies the multilinear blend of its copies
that the object's state selects (:meth:`~planners.plan.types.ImpactCopies.blend`), and the object leaves with
Eq. (5) applied to the blended robot's pre-impact velocity, plus the error. The result says whether the task
holds (STL robustness of the sampled trace), whether every object ends inside its final box, how far
out of its box the object ever was at an impact (|xi| <= 1: inside) and how much room the disc robot had
behind its contact (its centre one robot and object radius from the object's, against the push, inside the
world shrunk by its radius). A plan with delta promises all four for every error in [-delta, delta]^2 at
every impact (the room since ``IRPlannerConfig.contact_cones``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from impact_env.transport.scenario import Scenario
from planners.impact_law import mass_fractions
from planners.plan import BodyPlan, Plan, Segment
from planners.plan.contact_room import contact_centre, room_m
from planners.plan.funnels import box_coordinates


@dataclass
class Outcome:
    """One rollout. robustness: the task's STL robustness (m) on the trace sampled every control period;
    final_position_error_m / final_velocity_error_mps: per object, |state(tf) - plan(tf)| per axis;
    in_final_box: every object's final state within its final box; max_box_coordinate: the largest |xi|
    of an object's state at an impact (> 1: it left the box the copies cover); contact_room_m: the smallest
    distance (m) of the disc robot's centre at an impact inside the world shrunk by its radius and outside
    the obstacles grown by it (< 0: the robot would have to be beyond a wall or in an obstacle;
    :func:`contact_room`)."""

    robustness: float
    final_position_error_m: dict[str, np.ndarray]
    final_velocity_error_mps: dict[str, np.ndarray]
    in_final_box: bool
    max_box_coordinate: float
    positions: dict[str, np.ndarray]
    times_s: np.ndarray
    contact_room_m: float = np.inf

    @property
    def ok(self) -> bool:
        """The task holds, every object ends in its final box, stayed in its boxes and left the disc robot
        room behind every contact (to 1e-6)."""
        return (self.robustness >= -1e-6 and self.in_final_box and self.max_box_coordinate <= 1.0 + 1e-6
                and self.contact_room_m >= -1e-6)


def contact_room(scenario: Scenario, robot: str, obj: str, position: np.ndarray, push: np.ndarray) -> float:
    """Room (m) of the disc robot that gives the object at ``position`` the velocity change ``push`` (m/s):
    its centre is r_R + r_O behind the object's, against the push; the smallest distance of that centre
    inside the world box shrunk by r_R and outside every obstacle's bounding box grown by r_R (< 0: beyond a
    wall, or in an obstacle, as the planner's rows have it: :mod:`planners.offline.milp.contact_room`). A zero
    push leaves the side open: inf. The one measure of :mod:`planners.plan.contact_room`."""
    norm = float(np.hypot(*push))
    if norm <= 1e-12:
        return float("inf")
    return room_m(scenario, robot, contact_centre(scenario, robot, obj, position, np.asarray(push, float) / norm))


def rollout(plan: Plan, scenario: Scenario, errors: Sequence[np.ndarray] | np.ndarray) -> Outcome:
    """Fly ``plan`` by point masses with ``errors[i]`` (shape (2,)) added after impact i; see the module
    docstring. ``errors`` has one row per planned impact, in ``plan.impacts`` order."""
    if plan.planner != "ir":
        raise ValueError(f"rollout needs an impact-robust plan (planner 'ir'), got {plan.planner!r}")
    errors = np.asarray(errors, dtype=float).reshape(len(plan.impacts), 2)
    copies = {(c.robot, round(c.time_s, 9)): c for c in plan.copies}
    state = {o.name: (np.array(o.position_m, float), np.array(o.velocity_mps, float), 0.0) for o in scenario.objects}
    robots = {r.name: plan.bodies[r.name] for r in scenario.robots}
    worst, room = 0.0, float("inf")
    breaks: dict[str, list[tuple[float, np.ndarray, np.ndarray]]] = {o.name: [] for o in scenario.objects}
    for imp, err in zip(plan.impacts, errors):
        p0, v0, t0 = state[imp.object]
        p = p0 + (imp.time_s - t0) * v0
        c = copies[(imp.robot, round(imp.time_s, 9))]
        xi = box_coordinates(plan, c, p, v0)
        worst = max(worst, float(np.max(np.abs(xi))))
        before, after = c.blend(xi)
        robots[imp.robot] = _with_window(robots[imp.robot], c, before, after)
        dt = plan.funnels[imp.object].dt_s
        v_robot = (before[-1][-1] - before[-1][-2]) * (len(before[-1]) - 1) / dt
        _, _, m3, m4 = mass_fractions(scenario.body(imp.robot).mass_kg, scenario.body(imp.object).mass_kg,
                                      scenario.restitution)
        v1 = m3 * v_robot + m4 * v0 + err
        room = min(room, contact_room(scenario, imp.robot, imp.object, p, m3 * (v_robot - v0)))
        state[imp.object] = (p, v1, imp.time_s)
        breaks[imp.object].append((imp.time_s, p, v1))

    dt = scenario.control_period_s
    steps = round(scenario.formula.horizon_s / dt)
    times = np.arange(steps + 1) * dt
    trace = {name: body.position(times) for name, body in robots.items()}
    pos_err, vel_err, inside = {}, {}, True
    for o in scenario.objects:
        p0, v0 = np.array(o.position_m, float), np.array(o.velocity_mps, float)
        trace[o.name] = _piecewise_linear(times, p0, v0, breaks[o.name])
        tf = plan.tf_s
        p_end, v_end, t_end = state[o.name]
        p_tf = p_end + (tf - t_end) * v_end
        pos_err[o.name] = np.abs(p_tf - plan.bodies[o.name].position(tf))
        vel_err[o.name] = np.abs(v_end - plan.bodies[o.name].segments[-1].velocity(tf)[0])
        funnel = plan.funnels[o.name]
        inside &= bool(np.all(pos_err[o.name] <= np.asarray(funnel.final_box_m) + 1e-6)
                       and np.all(vel_err[o.name] <= np.asarray(funnel.final_box_mps) + 1e-6))
    from impact_env.stl import robustness

    rho = float(robustness(scenario.formula, trace, scenario.region_map(), dt=dt))
    return Outcome(rho, pos_err, vel_err, inside, worst, trace, times, room)


def _piecewise_linear(times: np.ndarray, p0: np.ndarray, v0: np.ndarray,
                      breaks: list[tuple[float, np.ndarray, np.ndarray]]) -> np.ndarray:
    out = p0 + np.outer(times, v0)
    for t_b, p_b, v_b in breaks:
        later = times >= t_b
        out[later] = p_b + np.outer(times[later] - t_b, v_b)
    return out


def _with_window(body: BodyPlan, copies, before: np.ndarray, after: np.ndarray) -> BodyPlan:
    """``body`` with its segments inside the copies' window replaced by the blended ones."""
    segments = list(body.segments)
    blended = list(before) + list(after)
    first = next(i for i, s in enumerate(segments) if abs(s.t0_s - copies.window_start_s) < 1e-9)
    for j, cps in enumerate(blended):
        s = segments[first + j]
        segments[first + j] = Segment(s.t0_s, s.t1_s, np.asarray(cps))
    return dataclasses.replace(body, segments=segments)


def worst_case_errors(plan: Plan, scale: float = 1.0) -> list[np.ndarray]:
    """Every sign pattern of errors of magnitude ``scale * delta`` on both axes of every impact (the vertices
    of the error set): 4^(number of impacts) rows of shape (impacts, 2)."""
    n = len(plan.impacts)
    d = scale * (plan.delta_mps or 0.0)
    out = []
    for code in range(4 ** n):
        signs = [((code >> (2 * i)) & 1, (code >> (2 * i + 1)) & 1) for i in range(n)]
        out.append(np.array([[d if sx else -d, d if sy else -d] for sx, sy in signs]))
    return out
