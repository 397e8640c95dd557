"""The inverse of the disc impact law (paper Eq. 6-7, :func:`planners.impact_law.disc_impact`): where and how fast
a robot must hit an object so that it leaves with a wanted velocity (docs/background.md#planner, item 5).

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

from planners.impact_law import disc_impact, mass_fractions

__all__ = ["ContactPlan", "disc_impact", "required_contact"]


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
