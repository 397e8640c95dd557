"""The circular two-body impact model (paper Eq. 6-7) and its closed-form inverse (docs/background.md#planner, item 5).

Frictionless discs that do not spin exchange momentum only along the contact normal n, the line of
centres at contact: in the contact frame the normal components follow the point-mass law (Eq. 5) and the
tangential ones are kept; Eq. 7 rotates back to the world frame.

The inverse needs no solver (the paper's replanner solves Eq. 7 numerically): to change an object's
velocity from v_O to v_des, the velocity change Delta = v_des - v_O can only lie along n, so
n = Delta / |Delta|; the robot's centre must be at x_O - (r_R + r_O) n at contact; along n Eq. 5 gives
v_On + |Delta| = m3 v_Rn + m4 v_On, and since m3 + m4 = 1, v_Rn = v_On + |Delta| / m3 (the robot always
approaches, at |Delta| / m3). The robot's tangential velocity is free; it is set to the object's, so the
approach is straight along n in the object's frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planners.offline.milp.impacts import mass_fractions


def disc_impact(p_robot, v_robot, m_robot: float, p_object, v_object, m_object: float, e: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """Post-impact velocities (robot, object) of two discs touching at these centres (Eq. 6-7)."""
    n = np.asarray(p_object, float) - np.asarray(p_robot, float)
    n /= np.linalg.norm(n)
    t = np.array([-n[1], n[0]])
    vr, vo = np.asarray(v_robot, float), np.asarray(v_object, float)
    m1, m2, m3, m4 = mass_fractions(m_robot, m_object, e)
    vrn, von = vr @ n, vo @ n
    if vrn - von <= 0.0:  # separating or sliding: no impulse
        return vr.copy(), vo.copy()
    return (m1 * vrn + m2 * von) * n + (vr @ t) * t, (m3 * vrn + m4 * von) * n + (vo @ t) * t


@dataclass
class ContactPlan:
    """What the robot must do at the impact (real units: m, m/s)."""

    normal: np.ndarray  # unit, from robot to object
    robot_position: np.ndarray  # robot centre at contact
    robot_velocity_before: np.ndarray
    robot_velocity_after: np.ndarray
    object_velocity_after: np.ndarray


def required_contact(object_position, object_velocity, desired_object_velocity, m_robot: float, r_robot: float,
                     m_object: float, r_object: float, e: float, min_change_mps: float = 1e-6) -> ContactPlan | None:
    """Where and how fast the robot must hit the object so that it leaves with ``desired_object_velocity``.

    Returns None when the object already has that velocity (within ``min_change_mps``): no impact needed.
    """
    vo = np.asarray(object_velocity, float)
    delta = np.asarray(desired_object_velocity, float) - vo
    size = float(np.linalg.norm(delta))
    if size < min_change_mps:
        return None
    n = delta / size
    t = np.array([-n[1], n[0]])
    m1, m2, m3, m4 = mass_fractions(m_robot, m_object, e)
    von = vo @ n
    vrn = von + size / m3
    v_before = vrn * n + (vo @ t) * t
    v_after = (m1 * vrn + m2 * von) * n + (vo @ t) * t
    return ContactPlan(normal=n, robot_position=np.asarray(object_position, float) - (r_robot + r_object) * n,
                       robot_velocity_before=v_before, robot_velocity_after=v_after,
                       object_velocity_after=vo + delta)
