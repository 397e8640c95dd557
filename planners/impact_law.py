"""The impact law: what a robot-object impact does to their velocities (paper Eq. 5-7), for every layer.

The planners' bodies are point masses (Assumption 1): along the line of impact momentum is conserved and
the relative velocity is reversed and scaled by the restitution e, which in the velocities before (-) and
after (+) reads, per axis,

    v_R+ = m1 v_R- + m2 v_O-,     v_O+ = m3 v_R- + m4 v_O-                                  (Eq. 5)
    m1 = (m_R - e m_O) / (m_R + m_O),  m2 = (1 + e) m_O / (m_R + m_O),
    m3 = (1 + e) m_R / (m_R + m_O),    m4 = (m_O - e m_R) / (m_R + m_O).

Frictionless discs that do not spin (the simulator's bodies) follow the same law along the contact normal
and keep their tangential velocities (Eq. 6-7). The MILP encodes the law (``offline/milp/impacts.py``), the
plan checks and the funnels verify it, and the online layer inverts it; all take it from here.
"""

from __future__ import annotations

from typing import Any

import numpy as np

Fractions = tuple[float, float, float, float]


def mass_fractions(m_r: float, m_o: float, e: float) -> Fractions:
    """(m1, m2, m3, m4) of Eq. (5) for robot mass ``m_r`` (kg), object mass ``m_o`` (kg), restitution ``e``."""
    s = m_r + m_o
    return (m_r - e * m_o) / s, (1 + e) * m_o / s, (1 + e) * m_r / s, (m_o - e * m_r) / s


def point_mass_law(fractions: Fractions, vr_in: Any, vo_in: Any) -> tuple[tuple[Any, Any], tuple[Any, Any]]:
    """Eq. (5) per axis: (robot, object) velocities after the impact from those before (m/s, 2 per body).

    The velocities may be numbers or the MILP's linear expressions (anything with ``*`` by a float and ``+``):
    the planner encodes the law with the same function that computes it."""
    m1, m2, m3, m4 = fractions
    vr_out = tuple(vr_in[a] * m1 + vo_in[a] * m2 for a in range(2))
    vo_out = tuple(vr_in[a] * m3 + vo_in[a] * m4 for a in range(2))
    return vr_out, vo_out


def disc_impact(p_robot, v_robot, m_robot: float, p_object, v_object, m_object: float, e: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """Post-impact velocities (robot, object) of two discs touching at these centres (Eq. 6-7): Eq. (5) along
    the line of centres, tangential velocities kept; no impulse if they are not approaching."""
    n = np.asarray(p_object, float) - np.asarray(p_robot, float)
    n /= np.linalg.norm(n)
    t = np.array([-n[1], n[0]])
    vr, vo = np.asarray(v_robot, float), np.asarray(v_object, float)
    m1, m2, m3, m4 = mass_fractions(m_robot, m_object, e)
    vrn, von = vr @ n, vo @ n
    if vrn - von <= 0.0:  # separating or sliding: no impulse
        return vr.copy(), vo.copy()
    return (m1 * vrn + m2 * von) * n + (vr @ t) * t, (m3 * vrn + m4 * von) * n + (vo @ t) * t
