"""Room for a disc robot behind every contact: the planners' robots are discs at impacts.

The copies of :mod:`planners.offline.milp.copies` are points that meet the object's box vertex at the
object's centre. The robot flown is a disc of radius r_R that touches the object (radius r_O) on the side
away from the push: its centre is at c = p - D n, D = r_R + r_O, n the unit direction of the push
(Delta v_O = m3 (v_R - v_O), Eq. 5). With a box vertex near a wall and the push away from it, c lies beyond
the wall: the disc robot cannot be there, it is pinned against the wall and knocks the object off
(two_objects at 1 x delta, ``docs/robustness.md``). These rows keep c inside the world shrunk by r_R for
every state in the box.

n is not linear in the variables. A binary per (robot, object, knot) and mode picks one of ``cones`` cones
of push directions, centred every 2 pi / cones from +x and each as wide as two steps (neighbours overlap by
half, so a spread of pushes up to one step wide always fits one), or the mode "any side"; their sum is the
impact binary. Every push the copies can deliver must lie in the picked cone: the product of the per-axis
ranges of v_R - v_O over the copies, which holds every blend of them. The room asked on each side of each
axis is D times the cone's extreme n_a ("any": D on every side). Exact along a cone's axis, conservative
across it (8 cones: 0.71 D beside a stop's path, where it needs ~0). The same box of robot centres must also
lie outside every solid obstacle grown by r_R (its bounding box: exact for the box obstacles of the shipped
scenarios), on one of its four sides picked by a binary: a contact in narrow_gap's gap put the disc 0.02 m
into the wall above it at the nominal push already, and it scraped the wall and missed the push by 8 delta.

The spatially robust planner takes the same rows when asked (``PlannerConfig.contact_cones``,
:func:`add_point_contact_room`): one robot curve and one object point per impact, so the push's range and the
object's box are single points. Both planners build them through :func:`_add_rows`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from impact_env.transport.scenario import Body
from planners.offline.milp.boxes import ObjectBox
from planners.offline.milp.copies import SIGNS, RobotCopies
from planners.offline.milp.impacts import ImpactVars
from planners.offline.milp.model import LinExpr, Model
from planners.offline.milp.trajectories import ObjectTrajectory, RobotTrajectory, velocity_bound

GROUP = "contact room"


def cone_extremes(cones: int) -> list[tuple[tuple[float, float], tuple[float, float]]]:
    """Per cone m (centred on the angle 2 pi m / cones, half-width 2 pi / cones), ((min n_x, max n_x),
    (min n_y, max n_y)) over the unit directions n in it."""
    step = 2 * math.pi / cones
    out = []
    for m in range(cones):
        lo, hi = (m - 1) * step, (m + 1) * step
        angles = [lo, hi] + [j * math.pi / 2 for j in range(-4, 5) if lo < j * math.pi / 2 < hi]
        xs, ys = [math.cos(a) for a in angles], [math.sin(a) for a in angles]
        out.append(((min(xs), max(xs)), (min(ys), max(ys))))
    return out


@dataclass(frozen=True)
class ContactRange:
    """What the rows of one (robot, object, knot) read: per axis, the lowest and highest push v_R - v_O the
    robot can deliver there and the lowest and highest position of the object's centre (LinExprs)."""

    push: tuple[tuple[LinExpr, LinExpr], tuple[LinExpr, LinExpr]]
    position: tuple[tuple[LinExpr, LinExpr], tuple[LinExpr, LinExpr]]


def add_contact_room(model: Model, robots: list[RobotCopies], boxes: list[ObjectBox], impacts: ImpactVars,
                     world_box: tuple[float, float, float, float], cones: int = 8,
                     obstacles: Sequence[tuple[float, float, float, float]] = ()) -> dict[tuple[str, str, int],
                                                                                         list[LinExpr]]:
    """The rows of the module docstring for every robot, object and interior knot of the impact-robust model;
    ``obstacles``: the solid obstacles' bounding boxes (xmin, xmax, ymin, ymax).

    Returns the mode binaries per (robot, object, knot) (the cones', then "any side"), for tests.
    """

    def ranges(r: RobotCopies, box: ObjectBox, k: int, m_axis: list[float]) -> ContactRange:
        # per axis, the push of every copy, v_R - v_O at its velocity vertex, within [low, high]; a blend's push
        # lies in that product (copy i's x with copy j's y)
        name = f"{r.spec.name},{box.centre.spec.name},{k}"
        span = [[model.add_var(-m_axis[a], m_axis[a], name=f"push_{side}[{name}]") for side in ("low", "high")]
                for a in range(2)]
        for a in range(2):
            for c, (_, s_v) in zip(r.copies, SIGNS):
                push = c.velocity_end(k - 1)[a] - box.vertex_velocity_before(k, s_v, a)
                model.add([push >= span[a][0], push <= span[a][1]], group=GROUP)
        position = tuple((box.vertex_position(k, -1, a), box.vertex_position(k, 1, a)) for a in range(2))
        return ContactRange((tuple(span[0]), tuple(span[1])), position)  # type: ignore[arg-type]

    return _add_rows(model, [(r.spec, r) for r in robots], [(b.centre.spec, b) for b in boxes], impacts,
                     world_box, cones, obstacles, ranges)


def add_point_contact_room(model: Model, robots: list[RobotTrajectory], objects: list[ObjectTrajectory],
                           impacts: ImpactVars, world_box: tuple[float, float, float, float], cones: int = 8,
                           obstacles: Sequence[tuple[float, float, float, float]] = ()
                           ) -> dict[tuple[str, str, int], list[LinExpr]]:
    """The same rows for the spatially robust model (``PlannerConfig.contact_cones``): one robot curve and one
    object point per impact, so the push and the position are single expressions (no spans)."""

    def ranges(r: RobotTrajectory, o: ObjectTrajectory, k: int, m_axis: list[float]) -> ContactRange:
        push = [r.velocity_end(k - 1)[a] - o.velocity(k - 1)[a] for a in range(2)]
        p = o.position_at_knot(k)
        return ContactRange(((push[0], push[0]), (push[1], push[1])), ((p[0], p[0]), (p[1], p[1])))

    return _add_rows(model, [(r.spec, r) for r in robots], [(o.spec, o) for o in objects], impacts, world_box,
                     cones, obstacles, ranges)


def _add_rows(model: Model, robots: list[tuple[Body, Any]], objects: list[tuple[Body, Any]], impacts: ImpactVars,
              world_box: tuple[float, float, float, float], cones: int,
              obstacles: Sequence[tuple[float, float, float, float]],
              ranges: Callable[[Any, Any, int, list[float]], ContactRange]) -> dict[tuple[str, str, int],
                                                                                    list[LinExpr]]:
    """The rows of the module docstring, for (spec, handle) pairs of robots and objects; ``ranges(robot,
    object, k, per-axis push bound)`` gives a :class:`ContactRange`."""
    if cones < 4:
        raise ValueError(f"cones must be >= 4 (each cone at most a half-plane), got {cones}")
    n = robots[0][1].grid.intervals
    step = 2 * math.pi / cones
    extremes = cone_extremes(cones) + [((-1.0, 1.0), (-1.0, 1.0))]
    # the cones' edges as half-planes e . d >= 0 (inward normals of the two rays)
    edges = [((-math.sin((m - 1) * step), math.cos((m - 1) * step)),
              (math.sin((m + 1) * step), -math.cos((m + 1) * step))) for m in range(cones)]
    lower = (world_box[0], world_box[2])
    upper = (world_box[1], world_box[3])
    extent = max(world_box[1] - world_box[0], world_box[3] - world_box[2])
    out: dict[tuple[str, str, int], list[LinExpr]] = {}
    for r_spec, r in robots:
        vr = velocity_bound(r_spec)
        for o_spec, o in objects:
            vo = velocity_bound(o_spec)
            reach = r_spec.radius_m + o_spec.radius_m
            # |d_a| <= v_R + v_O (the bodies' velocities are within the bounds), |e . d| <= sqrt(2) max_a of it
            m_axis = [vr[a] + vo[a] for a in range(2)]
            m_cone = math.sqrt(2) * max(m_axis)
            # a relaxed room row asks at most r_R + D more than the object's own box keeps: the world suffices
            m_room = extent + r_spec.radius_m + reach
            for k in range(1, n):
                z = impacts.z[(r_spec.name, o_spec.name, k)]
                picks = [model.add_binary(name=f"side[{r_spec.name},{o_spec.name},{k},{m}]") for m in range(cones + 1)]
                out[(r_spec.name, o_spec.name, k)] = picks
                model.add(sum(picks, LinExpr()) - z == 0, group=GROUP)
                contact = ranges(r, o, k, m_axis)
                # the box of pushes must lie in the picked cone: on each edge e . d >= 0 at the box's corner
                # that is lowest along e ("any": no rows)
                for pick, pair in zip(picks, edges):
                    for e in pair:
                        corner = sum((contact.push[a][0] * e[a] if e[a] > 0 else contact.push[a][1] * e[a]
                                      for a in range(2)), LinExpr())
                        model.add(corner >= (1 - pick) * (-m_cone), group=GROUP)
                miss = 1 - z
                sides = []
                for a in range(2):
                    # the robot's centre p - D n on the low side of the box, and on its high side
                    need_low = sum((pick * (reach * ext[a][1]) for pick, ext in zip(picks, extremes)), LinExpr())
                    need_high = sum((pick * (reach * ext[a][0]) for pick, ext in zip(picks, extremes)), LinExpr())
                    low_side = contact.position[a][0] - need_low
                    high_side = contact.position[a][1] - need_high
                    model.add(low_side >= lower[a] + r_spec.radius_m - miss * m_room, group=GROUP)
                    model.add(high_side <= upper[a] - r_spec.radius_m + miss * m_room, group=GROUP)
                    sides.append((low_side, high_side))
                for j, obstacle in enumerate(obstacles):
                    _outside_obstacle(model, sides, obstacle, r_spec.radius_m, z, m_room + extent,
                                      f"{r_spec.name},{o_spec.name},{k},{j}")
    return out


def _outside_obstacle(model: Model, sides: list[tuple[LinExpr, LinExpr]], obstacle: tuple[float, float, float, float],
                      radius: float, z: LinExpr, big_m: float, name: str) -> None:
    """The box of robot centres (``sides``: per axis its low and high side) left of, right of, below or above
    the obstacle grown by ``radius``, one of them picked by a binary, when the impact happens (``z``)."""
    (lx, hx), (ly, hy) = sides
    x0, x1, y0, y1 = obstacle
    picks = [model.add_binary(name=f"clear_{side}[{name}]") for side in ("left", "right", "below", "above")]
    model.add(sum(picks, LinExpr()) - z >= 0, group=GROUP)
    model.add(hx <= x0 - radius + (1 - picks[0]) * big_m, group=GROUP)
    model.add(lx >= x1 + radius - (1 - picks[1]) * big_m, group=GROUP)
    model.add(hy <= y0 - radius + (1 - picks[2]) * big_m, group=GROUP)
    model.add(ly >= y1 + radius - (1 - picks[3]) * big_m, group=GROUP)

