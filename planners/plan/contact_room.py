"""Contact room: a disc robot must fit where a plan's impact puts it.

The planners' bodies are points, so a plan may have a robot meet the object's centre wherever the object is.
The robot flown is a disc of radius r_R touching the object (radius r_O) on the side away from the push: its
centre is c = p - D n, D = r_R + r_O, p the object's position at the impact and n the unit direction of the
object's velocity change (:func:`planners.plan.handover.unit_change`). With the object next to a wall and the
push away from it, c lies beyond the wall: the disc is pinned there and the push fails (throw_and_catch_47:
R1 must push O1 down from above at y 4.5, its centre would be at y 4.9 in a world 5.0 high).

The room of a contact is the signed distance of c inside the world box shrunk by r_R and outside every
obstacle's bounding box grown by r_R (< 0: no room). The bounding box is what the impact-robust planner's rows
use (:mod:`planners.offline.milp.contact_room`; exact for the shipped box obstacles, conservative for others)
and what its rollout measures (:func:`planners.offline.guarantee.contact_room` calls :func:`room_m`). The
spatially robust planner keeps every contact's room with the same rows when asked
(``PlannerConfig.contact_cones``); this module measures a plan that was made without them
(``docs/generated_tasks.md``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from impact_env.transport.scenario import Scenario
from planners.plan.handover import unit_change
from planners.plan.types import PlanLike, PlannedImpact

__all__ = ["ROOM_TOLERANCE_M", "Contact", "contact_centre", "contacts", "contacts_without_room", "obstacle_bounds",
           "room_m"]

ROOM_TOLERANCE_M = 1e-3
"""A contact with less than minus this much room (m) has none: well below the 1e-6 of the planners' rows, well
above what a disc robot's controller can hold."""


def obstacle_bounds(obstacle) -> tuple[float, float, float, float]:
    """(xmin, xmax, ymin, ymax) of a scenario's obstacle (a :class:`~impact_env.transport.scenario.Region`)."""
    v = obstacle.polygon.vertices
    return float(v[:, 0].min()), float(v[:, 0].max()), float(v[:, 1].min()), float(v[:, 1].max())


def contact_centre(scenario: Scenario, robot: str, obj: str, position, normal) -> np.ndarray:
    """The disc robot's centre (m) when it gives the object at ``position`` a push along the unit ``normal``:
    r_R + r_O behind the object's centre, against the push."""
    reach = scenario.body(robot).radius_m + scenario.body(obj).radius_m
    return np.asarray(position, float) - reach * np.asarray(normal, float)


def room_m(scenario: Scenario, robot: str, centre) -> float:
    """The room (m) of ``robot``'s centre at ``centre``: its smallest distance inside the world box shrunk by
    the robot's radius and outside every obstacle's bounding box grown by it (per axis, as the planner's rows
    have it); < 0: beyond a wall or in an obstacle."""
    r = scenario.body(robot).radius_m
    x, y = (float(c) for c in centre)
    xmin, xmax, ymin, ymax = scenario.world_box
    room = min(x - xmin - r, xmax - r - x, y - ymin - r, ymax - r - y)
    for obstacle in scenario.obstacles:
        x0, x1, y0, y1 = obstacle_bounds(obstacle)
        room = min(room, max(x0 - r - x, x - x1 - r, y0 - r - y, y - y1 - r))
    return float(room)


@dataclass
class Contact:
    """Where ``robot``'s disc must be at its impact on ``object`` at ``time_s``: ``centre`` (m) and its
    ``room`` (m, :func:`room_m`); ``impact``: the planned impact."""

    robot: str
    object: str
    time_s: float
    centre: tuple[float, float]
    room_m: float
    impact: PlannedImpact | None = field(default=None, repr=False, compare=False)

    def flyable(self, tolerance_m: float = ROOM_TOLERANCE_M) -> bool:
        """True if the disc fits there, to ``tolerance_m``."""
        return self.room_m >= -tolerance_m

    def describe(self) -> str:
        x, y = self.centre
        return (f"{self.robot} on {self.object} at {self.time_s:.2f} s: its centre would be at ({x:.3f}, {y:.3f}) m, "
                f"{-self.room_m:.3f} m beyond a wall or into an obstacle")

    def to_dict(self) -> dict:
        """The contact as a JSON record (the planned impact left out). Nothing in the planners stores it yet:
        the repair that put it in ``plan.stats`` was not kept (``docs/generated_tasks.md``)."""
        return {"robot": self.robot, "object": self.object, "time_s": self.time_s, "centre_m": list(self.centre),
                "room_m": self.room_m}


def contacts(plan: PlanLike, scenario: Scenario) -> list[Contact]:
    """The plan's contacts in time order, one per impact that changes its object's velocity (an impact that
    hardly does leaves the side open)."""
    out = []
    for impact in sorted(plan.impacts, key=lambda i: i.time_s):
        normal = unit_change(impact)
        if normal is None:
            continue
        centre = contact_centre(scenario, impact.robot, impact.object, impact.position, normal)
        out.append(Contact(impact.robot, impact.object, impact.time_s, (float(centre[0]), float(centre[1])),
                           room_m(scenario, impact.robot, centre), impact=impact))
    return out


def contacts_without_room(plan: PlanLike, scenario: Scenario,
                          tolerance_m: float = ROOM_TOLERANCE_M) -> list[Contact]:
    """The plan's contacts with less than ``-tolerance_m`` of room."""
    return [c for c in contacts(plan, scenario) if not c.flyable(tolerance_m)]
