"""The braking schedule that ends a tether plan, and the braking distances the expert brakes by.

A pull reels the cargo toward its anchor at ``w``; in the goal box it must stop and stay. Without inertia (the
thesis's Eq. 5, the ``kinematic`` fidelity) letting go stops it. With inertia (``reel``, ``force``) a released
cargo drifts on, so the last pull ends with a brake: a tether toward an anchor behind the motion, attached
``t_switch`` ahead and held (its winch locked), takes up the motion away from that anchor within the winch force
limit, and the pulling tether is held too once the cargo is its braking distance from the stop point. The anchor
chosen is the one most nearly opposite the motion that the stop point sees, outside its stop radius with a
margin, so that what is left of the velocity (the part across the brake tether) is small.
"""

from __future__ import annotations

import numpy as np

from impact_env.tether.station import Station
from planners.tether.plan import HoldSchedule, TetherPlan

BEHIND_COS = -0.5  # a brake anchor lies within 60 degrees of straight behind the motion
CLEAR_M = 0.3  # and at least this much farther than its stop radius from the stop point


def brake_anchor(station: Station, point: np.ndarray, direction: np.ndarray, allowed: list[int] | None = None,
                 sight: np.ndarray | None = None) -> int | None:
    """The anchor most nearly opposite ``direction`` (the motion) seen from ``point``, outside its stop radius by
    :data:`CLEAR_M`, within 60 degrees of straight behind; None if there is none. ``sight`` is the line-of-sight
    mask from the point if known."""
    norm = float(np.linalg.norm(direction))
    if norm <= 0.0:
        return None
    u = np.asarray(direction, dtype=float) / norm
    d = station.anchor_positions - np.asarray(point, dtype=float)
    dist = np.linalg.norm(d, axis=1)
    cosines = (d @ u) / np.maximum(dist, 1e-12)
    ok = (dist > station.stop_radius_m + CLEAR_M) & (cosines < BEHIND_COS)
    if allowed is not None:
        mask = np.zeros(station.n_anchors, dtype=bool)
        mask[list(allowed)] = True
        ok &= mask
    if not ok.any():
        return None
    ok &= station.line_of_sight(point) if sight is None else sight
    if not ok.any():
        return None
    return int(np.argmin(np.where(ok, cosines, np.inf)))


def with_hold(plan: TetherPlan, station: Station, allowed: list[int] | None = None) -> TetherPlan:
    """``plan`` with the hold schedule of its last pull (its stop point and brake anchor)."""
    if not plan.pulls:
        plan.hold = HoldSchedule(stop_m=(plan.start_m[0], plan.start_m[1]), brake_anchor=None)
        return plan
    last = plan.pulls[-1]
    motion = np.asarray(last.end_m) - np.asarray(last.start_m)
    plan.hold = HoldSchedule(stop_m=(last.end_m[0], last.end_m[1]),
                             brake_anchor=brake_anchor(station, np.asarray(last.end_m), motion, allowed))
    return plan


def braking_distance_m(fidelity: str, speed_mps: float, mass_kg: float, force_N: float, w_mps: float) -> float:
    """How far (m) a held tether takes to stop a cargo moving away from its anchor at ``speed_mps``: none
    without inertia; ``v^2 m / (2 F)`` under ``reel`` (the joint at its force limit); ``v m w / F`` under
    ``force`` (the held tension ``F v / w`` decays the speed with the time constant ``m w / F``)."""
    if fidelity == "kinematic":
        return 0.0
    if fidelity == "reel":
        return speed_mps * speed_mps * mass_kg / (2.0 * force_N)
    return speed_mps * mass_kg * w_mps / force_N
