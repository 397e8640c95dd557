"""Flying an impact-robust plan: its robot copies as contingency plans for every object state in the box.

An impact-robust plan (:mod:`planners.offline.impact_robust`) carries, for each impact, four copies of the
impacting robot's curve that meet the vertices of the object's state box, and a feedback law: an object hit
at normalised box coordinates xi leaves with v_des = t_c + A xi_p + B xi_v (the copies' blend), and the next
impact's copies are ready for wherever that sends it (:mod:`planners.plan.funnels`). :class:`CopyContact`
gives the replanner (Eq. 29) the contact for that feedback velocity (extrapolated outside the box), and makes
the blend of copies that matches the object's predicted state the robot's plan inside the copy window
(:meth:`CopyContact.observe`, :meth:`CopyContact.plan_state`). A plan without copies (a spatially robust
plan, or the remainder a mission re-plan splices in) is flown by the ``fallback`` strategy.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from impact_env.transport.scenario import Body, Scenario
from planners import bezier
from planners.online.impact_model import ContactPlan, required_contact
from planners.online.reference import ContactQuery, ContactStrategy, PlanContact
from planners.plan import ImpactCopies, Plan, PlannedImpact
from planners.plan.funnels import box_coordinates, copy_targets


def copies_of(plan: Plan, impact: PlannedImpact) -> ImpactCopies | None:
    """The copies recorded for ``impact`` in ``plan`` (None for a plan without them)."""
    for c in plan.copies:
        if c.robot == impact.robot and c.object == impact.object and abs(c.time_s - impact.time_s) < 1e-6:
            return c
    return None


def feedback_velocity(plan: Plan, scenario: Scenario, copies: ImpactCopies, xi: np.ndarray) -> np.ndarray:
    """v_des = t_c + A xi_p + B xi_v per axis, from the copies' targets (Eq. 5 at each box vertex)."""
    targets = copy_targets(copies, plan, scenario)  # (4, 2)
    s = np.asarray(copies.signs, dtype=float)
    t_c, a_fb, b_fb = targets.mean(axis=0), s[:, 0] @ targets / 4.0, s[:, 1] @ targets / 4.0
    xi = np.asarray(xi, dtype=float).reshape(2, 2)
    return t_c + a_fb * xi[:, 0] + b_fb * xi[:, 1]


class CopyContact:
    """The :class:`~planners.online.reference.ContactStrategy` of an impact-robust plan (module docstring).

    Args:
        scenario: the scenario flown (masses and nominal restitution of the plan's feedback law).
        fallback: the strategy for impacts without copies (default :class:`PlanContact`).
    """

    def __init__(self, scenario: Scenario, fallback: ContactStrategy | None = None) -> None:
        self.scenario = scenario
        self.fallback = fallback or PlanContact()
        self._blends: dict[tuple[str, float], tuple[ImpactCopies, np.ndarray, np.ndarray]] = {}
        self.xi: dict[tuple[str, float], np.ndarray] = {}  # latest box coordinates per impact (for reports)

    def reset(self) -> None:
        self._blends.clear()
        self.xi.clear()

    # ---------------------------------------------------------------------------------- the strategy
    def contact(self, query: ContactQuery) -> ContactPlan | None:
        copies = copies_of(query.plan, query.impact)
        if copies is None:
            return self.fallback.contact(query)
        xi = box_coordinates(query.plan, copies, query.object_position, query.object_velocity)
        v_des = feedback_velocity(query.plan, self.scenario, copies, xi)
        m_r, m_o = query.masses
        return required_contact(query.object_position, query.object_velocity, v_des, m_r, query.robot.radius_m,
                                m_o, query.obj.radius_m, query.restitution)

    def observe(self, plan: Plan, robot: Body, t: float, impact: PlannedImpact | None,
                object_state: Callable[[str, float], tuple[np.ndarray, np.ndarray]]) -> None:
        """Inside the copy window of ``robot``'s next impact and before it, blend the copies for the object's
        state predicted at the impact (``object_state(name, t)`` -> position, velocity just before)."""
        if impact is None or t >= impact.time_s:
            return
        copies = copies_of(plan, impact)
        if copies is None or t < copies.window_start_s - 1e-9:
            return
        p, v = object_state(impact.object, impact.time_s)
        xi = box_coordinates(plan, copies, p, v)
        before, after = copies.blend(xi)
        key = (robot.name, round(impact.time_s, 6))
        self._blends[key] = (copies, before, after)
        self.xi[key] = xi

    def plan_state(self, plan: Plan, name: str, times: np.ndarray, sampled: np.ndarray) -> np.ndarray:
        """``sampled`` ([x, y, vx, vy] of robot ``name`` from the plan at ``times``) with the blended copies
        where a window of one of its impacts has a blend (in place; returned)."""
        for (robot, _), (copies, before, after) in self._blends.items():
            if robot != name or not any(c is copies for c in plan.copies):  # a blend of a plan since replaced
                continue
            mask = (times >= copies.window_start_s - 1e-9) & (times <= copies.window_end_s + 1e-9)
            if not np.any(mask):
                continue
            segments = list(before) + list(after)
            dt = (copies.window_end_s - copies.window_start_s) / len(segments)
            tm = times[mask]
            k = np.clip(np.floor((tm - copies.window_start_s) / dt + 1e-9).astype(int), 0, len(segments) - 1)
            s = np.clip((tm - copies.window_start_s - k * dt) / dt, 0.0, 1.0)
            out = np.empty((len(tm), 4))
            for j in np.unique(k):
                sel = k == j
                cps = segments[j]
                out[sel, :2] = bezier.evaluate(cps, s[sel])
                out[sel, 2:] = bezier.evaluate(bezier.derivative(cps), s[sel]) / dt
            sampled[mask] = out
        return sampled
