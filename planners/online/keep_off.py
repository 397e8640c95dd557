"""Keep-off constraints of the MPC and limits of the replanned segments ("safe segments").

The offline planner keeps robots apart (Eq. 26) and out of obstacles with their radii, but the online layer
re-solves segments and tracks them with an MPC, and the paper's controller keeps a robot off the nearest
object only. Here every robot, every control step, also gets:

- in the MPC, a disc keep-off around each other robot's predicted path (its previous MPC prediction:
  the robots are controlled together, so the prediction is the best guess of where it will be) and a fixed
  half-plane for the nearest wall or obstacle face within reach, with the robot's radius and a margin;
- in the replanner, :class:`SegmentLimits`: the world box shrunk by the radius, the face of every obstacle
  within reach that the robot is beyond, and the other robots' planned paths.

Near a planned impact the object's keep-off is lifted (the contact needs the radii to touch), as before.
"""

from __future__ import annotations

import numpy as np

from impact_env.transport.scenario import Body, Scenario
from planners.online.mpc import AvoidSpec, HalfPlaneSpec
from planners.online.replanner import SegmentLimits, obstacle_half_planes
from planners.plan import PlannedImpact

_BOX_NORMALS = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])


def object_keep_off(robot: Body, objects: list[Body], t: float, times: np.ndarray, position: np.ndarray,
                    object_states: dict[str, np.ndarray], impacts: list[PlannedImpact],
                    pending: PlannedImpact | None, margin_m: float, contact_window_s: float,
                    velocity: np.ndarray | None = None, braking_mps2: float | None = None) -> AvoidSpec | None:
    """Keep off the nearest object's predicted (free-flight) path, except around this robot's planned
    impacts on it and, while an impact is pending, from shortly before it on (the object's motion after
    the impact is the planned one, not the free flight). ``object_states``: name -> [x, y, vx, vy].

    With the robot's ``velocity`` and a deceleration ``braking_mps2`` (m/s^2), the keep-off distance grows by
    the robot's stopping distance at its closing speed on the object, v^2 / (2 a): the MPC's horizon (1 s) is
    shorter than the time to stop from the robot's top speed (0.3 m/s per axis at 0.17 m/s^2), so a keep-off of
    the radii alone is seen too late to brake for (:func:`braking_margin`). On the object of the impact the
    robot approaches (``pending``), only the distance to slow to the plan's relative speed at that impact."""
    if not objects:
        return None
    obj = objects[0] if len(objects) == 1 else \
        min(objects, key=lambda o: float(np.hypot(*(object_states[o.name][:2] - position))))
    return _keep_off(robot, obj, t, times, position, object_states, impacts, pending, margin_m, contact_window_s,
                     velocity, braking_mps2)


def objects_keep_off(robot: Body, objects: list[Body], count: int, t: float, times: np.ndarray,
                     position: np.ndarray, object_states: dict[str, np.ndarray], impacts: list[PlannedImpact],
                     pending: PlannedImpact | None, margin_m: float, contact_window_s: float,
                     velocity: np.ndarray | None = None, braking_mps2: float | None = None) -> list[AvoidSpec]:
    """:func:`object_keep_off` for each of the ``count`` objects nearest the robot (nearest first): a robot on
    its way to one object between two can meet the one it is not nearest to."""
    near = sorted(objects, key=lambda o: float(np.hypot(*(object_states[o.name][:2] - position))))[:count]
    return [_keep_off(robot, obj, t, times, position, object_states, impacts, pending, margin_m, contact_window_s,
                      velocity, braking_mps2) for obj in near]


def braking_margin(position: np.ndarray, velocity: np.ndarray, object_state: np.ndarray, braking_mps2: float,
                   allowed_mps: float = 0.0) -> float:
    """The distance (m) the robot needs to slow from its closing speed on an object to ``allowed_mps``:
    (v_c^2 - v_allowed^2) / (2 a), v_c the relative velocity along the line from the robot to the object's
    centre; 0 when moving apart or closing no faster than allowed. ``object_state``: [x, y, vx, vy]."""
    d = np.asarray(object_state[:2], float) - np.asarray(position, float)
    dist = float(np.hypot(*d))
    if dist < 1e-9:
        return 0.0
    closing = max(0.0, float(d @ (np.asarray(velocity, float) - np.asarray(object_state[2:4], float))) / dist)
    return max(0.0, closing * closing - allowed_mps * allowed_mps) / (2.0 * braking_mps2)


def _keep_off(robot: Body, obj: Body, t: float, times: np.ndarray, position: np.ndarray,
              object_states: dict[str, np.ndarray], impacts: list[PlannedImpact], pending: PlannedImpact | None,
              margin_m: float, contact_window_s: float, velocity: np.ndarray | None,
              braking_mps2: float | None) -> AvoidSpec:
    s = object_states[obj.name]
    centers = s[:2] + np.outer(times - t, s[2:4])
    active = np.ones(len(times), dtype=bool)
    for imp in impacts:
        if imp.robot == robot.name and imp.object == obj.name:
            active &= np.abs(times - imp.time_s) > contact_window_s
    if pending is not None and pending.object == obj.name:
        active &= times < pending.time_s - contact_window_s
    extra = 0.0
    if velocity is not None and braking_mps2 is not None:
        # the contact the robot approaches on this object is met at the plan's relative speed: only closing
        # faster than that needs room to slow down (a push at speed is the plan, not a collision)
        allowed = 0.0
        if pending is not None and pending.robot == robot.name and pending.object == obj.name:
            allowed = float(np.hypot(*(np.subtract(pending.robot_velocity_before, pending.object_velocity_before))))
        extra = braking_margin(position, velocity, s, braking_mps2, allowed)
    return AvoidSpec(centers=centers, min_distance=robot.radius_m + obj.radius_m + margin_m + extra, active=active)


def robot_keep_off(robot: Body, other: Body, centers: np.ndarray, margin_m: float) -> AvoidSpec:
    """Keep off another robot's predicted centres (N+1, 2) by both radii plus a margin."""
    return AvoidSpec(centers=centers, min_distance=robot.radius_m + other.radius_m + margin_m,
                     active=np.ones(len(centers), dtype=bool))


def boundary_keep_off(scenario: Scenario, robot: Body, position: np.ndarray, n_nodes: int, reach_m: float,
                      margin_m: float) -> HalfPlaneSpec | None:
    """The nearest wall of the world box or face of an obstacle, if within ``reach_m``, as a half-plane that
    keeps the robot's disc (plus a margin) out of it."""
    xmin, xmax, ymin, ymax = scenario.world_box
    r = robot.radius_m + margin_m
    p = np.asarray(position, float)
    # inward normals of the walls: n . p >= offset keeps the centre r inside
    candidates = [(p[0] - xmin, _BOX_NORMALS[0], xmin + r), (xmax - p[0], _BOX_NORMALS[1], -xmax + r),
                  (p[1] - ymin, _BOX_NORMALS[2], ymin + r), (ymax - p[1], _BOX_NORMALS[3], -ymax + r)]
    faces = obstacle_half_planes([o.polygon for o in scenario.obstacles], p, robot.radius_m, reach_m) \
        if scenario.obstacles else []
    for n, b in faces:
        candidates.append((float(n @ p - b) + robot.radius_m, n, b + margin_m))
    dist, normal, offset = min(candidates, key=lambda c: c[0])
    if dist > reach_m + robot.radius_m:
        return None
    return HalfPlaneSpec(normals=normal, offsets=offset, active=np.ones(n_nodes, dtype=bool))


def segment_limits(scenario: Scenario, robot: Body, position: np.ndarray, others: list,
                   separation_m: float, reach_m: float) -> SegmentLimits:
    """The replanner's :class:`SegmentLimits` for a robot at ``position``; ``others`` are callables
    ``times -> (N, 2)`` of the other robots' planned centres."""
    xmin, xmax, ymin, ymax = scenario.world_box
    r = robot.radius_m
    half_planes = obstacle_half_planes([o.polygon for o in scenario.obstacles], position, r, reach_m) \
        if scenario.obstacles else []
    return SegmentLimits(box=(xmin + r, xmax - r, ymin + r, ymax - r), half_planes=half_planes, others=others,
                         separation_m=separation_m)
