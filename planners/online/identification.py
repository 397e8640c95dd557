"""Online identification of the impact model: each pair's restitution (and mass ratio) from observed impacts.

Every robot-object contact that the environment reports (velocities of both bodies at first touch and at
separation) is one measurement. Frictionless discs exchange momentum only along the line of centres, so
the object's velocity change gives the contact normal exactly, n = dv_O / |dv_O| (Eq. 6-7), and along n the
point-mass law (Eq. 5) gives

    e = (v_O+ - v_R+) . n / (v_R- - v_O-) . n,        m_O / m_R = -(dv_R . n) / (dv_O . n).

The robot keeps thrusting during the contact, so its measured velocity after the contact is off by up
to a * duration; the restitution therefore uses the robot's post-impact velocity implied by momentum
conservation with the current mass-ratio estimate, v_R+ = v_R- - (m_O / m_R) dv_O, which the thrust does
not touch. The mass ratio is estimated from the robot's measured change (so it carries that thrust error,
which its uncertainty reflects).

Each quantity is a Gaussian estimate (mean, variance), updated by the standard conjugate rule; a
measurement's variance is that of a velocity error ``velocity_noise_mps`` divided by the normal approach
speed, so a glancing touch counts little. Pairs are estimated separately (on hardware two objects may be
of different materials); a pair not yet observed uses the estimate pooled over all pairs, and before any
impact the scenario file's value with the prior's uncertainty.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


@dataclass
class Estimate:
    """A Gaussian estimate: ``mean``, ``variance``, and how many measurements went into it."""

    mean: float
    variance: float
    count: int = 0

    @property
    def std(self) -> float:
        return math.sqrt(self.variance)

    def update(self, value: float, variance: float) -> None:
        """Conjugate update with one measurement of the given variance."""
        gain = self.variance / (self.variance + variance)
        self.mean += gain * (value - self.mean)
        self.variance *= 1.0 - gain
        self.count += 1


@dataclass
class ImpactMeasurement:
    """What one reported contact says about its pair."""

    time_s: float
    robot: str
    object: str
    restitution: float
    restitution_variance: float
    mass_ratio: float  # m_object / m_robot
    mass_ratio_variance: float
    normal_speed_mps: float


@dataclass
class IdentificationConfig:
    """Prior uncertainties and measurement noise of :class:`ImpactIdentifier`.

    ``restitution_prior_std`` and ``mass_ratio_prior_std``: how far the scenario file may be off;
    ``velocity_noise_mps``: error of a reported velocity along the normal (the contact is detected at a
    substep, so the line of centres is known exactly but the velocities carry about one substep of thrust);
    ``min_normal_speed_mps``: slower approaches are not used (their ratio is noise); ``use_mass_ratio``: let
    the contact inverse use the estimated mass ratio once its std is below ``mass_ratio_max_std``.
    """

    restitution_prior_std: float = 0.25
    mass_ratio_prior_std: float = 0.5
    velocity_noise_mps: float = 1e-3
    min_normal_speed_mps: float = 0.01
    use_mass_ratio: bool = False
    mass_ratio_max_std: float = 0.02


@dataclass
class ImpactIdentifier:
    """Estimates of restitution and mass ratio per (robot, object) pair, from ``info["impacts"]`` events.

    Args:
        restitution: the scenario file's restitution (the prior mean).
        masses: body name -> mass (kg) from the scenario file (the mass-ratio prior).
        robots, objects: names of the robots and objects (which reported contacts are robot-object).
    """

    restitution: float
    masses: dict[str, float]
    robots: frozenset[str]
    objects: frozenset[str]
    config: IdentificationConfig = field(default_factory=IdentificationConfig)

    def __post_init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        c = self.config
        self.pooled = Estimate(self.restitution, c.restitution_prior_std ** 2)
        self.pairs: dict[tuple[str, str], Estimate] = {}
        self.ratios: dict[tuple[str, str], Estimate] = {}
        self.measurements: list[ImpactMeasurement] = []

    def _prior_ratio(self, robot: str, obj: str) -> float:
        return self.masses[obj] / self.masses[robot]

    def mass_ratio(self, robot: str, obj: str) -> Estimate:
        """Estimate of m_object / m_robot for the pair (the scenario's ratio before any impact)."""
        return self.ratios.get((robot, obj)) or Estimate(self._prior_ratio(robot, obj),
                                                          (self.config.mass_ratio_prior_std
                                                           * self._prior_ratio(robot, obj)) ** 2)

    def estimate(self, robot: str, obj: str) -> Estimate:
        """The pair's restitution estimate; the pooled one if the pair has not been observed yet."""
        return self.pairs.get((robot, obj)) or self.pooled

    def restitution_for(self, robot: str, obj: str) -> float:
        return float(np.clip(self.estimate(robot, obj).mean, 0.0, 1.0))

    def masses_for(self, robot: str, obj: str) -> tuple[float, float]:
        """(m_robot, m_object) for the contact inverse: the file's masses, or with ``use_mass_ratio`` the
        robot's mass and the estimated ratio once it is certain enough."""
        m_r = self.masses[robot]
        ratio = self.mass_ratio(robot, obj)
        if self.config.use_mass_ratio and ratio.count and ratio.std <= self.config.mass_ratio_max_std:
            return m_r, m_r * ratio.mean
        return m_r, self.masses[obj]

    def observe(self, events: list[dict]) -> list[ImpactMeasurement]:
        """Update the estimates with the robot-object contacts among ``events``; returns what was used."""
        used = []
        for ev in events:
            pair = {ev["a"], ev["b"]}
            robot = next(iter(pair & self.robots), None)
            obj = next(iter(pair & self.objects), None)
            if robot is None or obj is None:
                continue
            m = self._measure(ev, robot, obj)
            if m is None:
                continue
            key = (robot, obj)
            c = self.config
            ratio = self.ratios.setdefault(key, Estimate(self._prior_ratio(robot, obj),
                                                         (c.mass_ratio_prior_std * self._prior_ratio(robot, obj)) ** 2))
            ratio.update(m.mass_ratio, m.mass_ratio_variance)
            self.pairs.setdefault(key, Estimate(self.restitution, c.restitution_prior_std ** 2)).update(
                m.restitution, m.restitution_variance)
            self.pooled.update(m.restitution, m.restitution_variance)
            self.measurements.append(m)
            used.append(m)
        return used

    def _measure(self, ev: dict, robot: str, obj: str) -> ImpactMeasurement | None:
        side = {ev["a"]: "a", ev["b"]: "b"}
        vr0 = np.asarray(ev[f"{side[robot]}_velocity_before"], float)
        vr1 = np.asarray(ev[f"{side[robot]}_velocity_after"], float)
        vo0 = np.asarray(ev[f"{side[obj]}_velocity_before"], float)
        vo1 = np.asarray(ev[f"{side[obj]}_velocity_after"], float)
        dvo = vo1 - vo0
        size = float(np.linalg.norm(dvo))
        if size < 1e-9:
            return None
        n = dvo / size
        approach = float((vr0 - vo0) @ n)
        if approach < self.config.min_normal_speed_mps:
            return None
        ratio_prior = self.mass_ratio(robot, obj).mean
        vr1_momentum = vr0 - ratio_prior * dvo  # Eq. 5's momentum balance, free of the robot's thrust
        e = float((vo1 - vr1_momentum) @ n) / approach
        sigma = self.config.velocity_noise_mps
        e_var = (sigma * (1.0 + e) / approach) ** 2 + 1e-8
        ratio = -float((vr1 - vr0) @ n) / size
        ratio_var = (sigma * (1.0 + ratio) / size) ** 2 + 1e-8
        return ImpactMeasurement(float(ev["time"]), robot, obj, e, e_var, ratio, ratio_var, approach)

    def report(self) -> dict:
        """JSON-ready estimates: pooled and per pair (mean, std, count)."""
        def row(est: Estimate) -> dict:
            return {"mean": est.mean, "std": est.std, "count": est.count}

        return {"restitution": {"pooled": row(self.pooled),
                                **{f"{r}-{o}": row(est) for (r, o), est in self.pairs.items()}},
                "mass_ratio": {f"{r}-{o}": row(est) for (r, o), est in self.ratios.items()}}
