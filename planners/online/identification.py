"""Online identification of the impact model: each pair's restitution (and mass ratio) from observed impacts.

Every robot-object contact the environment reports (both bodies' velocities at first touch and at
separation) is one measurement. The object's velocity change gives the contact normal n exactly (Eq. 6-7),
and along it the point-mass law (Eq. 5) gives

    e = (v_O+ - v_R+) . n / (v_R- - v_O-) . n,        m_O / m_R = -(dv_R . n) / (dv_O . n),

with v_R+ from momentum (the robot thrusts during the contact). Each is a Gaussian estimate per pair, updated
by the conjugate rule, pooled over the pairs until a pair is observed, and the scenario file's value before
any impact. With ``IdentificationConfig.significance = k`` an estimate replaces the file's value only when
the measurements alone put it more than k standard errors away (:func:`significance_test`).

Why each step, and the significance test's derivation: ``docs/expert_design.md#identification``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from impact_env.config_checks import check_flag, check_number
from planners.errors import PlannerError


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
    restitution_robot_side: float | None = None  # the robot's reading of the same impact (module docstring)

    @property
    def test_variance(self) -> float:
        """v_i of the significance test: the larger of the assumed variance and the squared difference of the
        object's and the robot's readings; infinite (the measurement does not count) when the robot's change
        gives no reading, as when something else touched the robot during the contact."""
        if self.restitution_robot_side is None:
            return math.inf
        return max(self.restitution_variance, (self.restitution_robot_side - self.restitution) ** 2)


@dataclass(frozen=True)
class Significance:
    """The significance test's verdict on a set of measurements against the file's restitution.

    ``mean`` (m) and ``std_of_mean`` (s_m) as in the module docstring, ``z = |m - e_file| / s_m``, ``count``
    measurements; ``in_use``: z > k, the estimate replaces the file's value.
    """

    mean: float
    std_of_mean: float
    z: float
    count: int
    in_use: bool


def significance_test(values: list[float], variances: list[float], reference: float, k: float) -> Significance:
    """Does the weighted mean of ``values`` (with ``variances``) differ from ``reference`` by more than ``k``
    standard errors? The standard error is inflated by the Birge ratio when the values scatter more than
    their variances allow (module docstring). Values of infinite variance do not count; none left: not in
    use."""
    keep = [(v, var) for v, var in zip(values, variances, strict=True) if math.isfinite(var)]
    if not keep:
        return Significance(reference, math.inf, 0.0, 0, False)
    e = np.array([v for v, _ in keep], float)
    w = 1.0 / np.array([var for _, var in keep], float)
    mean = float(w @ e / w.sum())
    birge = float(w @ (e - mean) ** 2) / (len(e) - 1) if len(e) > 1 else 1.0
    std = math.sqrt(max(1.0, birge) / float(w.sum()))
    z = abs(mean - reference) / std
    return Significance(mean, std, z, len(e), bool(z > k))


@dataclass(frozen=True)
class IdentificationConfig:
    """Prior uncertainties and measurement noise of :class:`ImpactIdentifier`.

    ``significance`` is off by default for now: turning it on changes every published benchmark cell that
    flies identification, and those must be flown again before the default can change (3 is the value
    measured to keep the file's restitution under post-impact noise and still take a 0.1 mismatch after one
    noise-free impact; see ``benchmarks/identification_noise.py``).
    """

    restitution_prior_std: float = 0.25
    """How far the scenario file's restitution may be off (standard deviation, dimensionless)."""
    mass_ratio_prior_std: float = 0.5
    """How far the file's mass ratio m_object / m_robot may be off (standard deviation, relative)."""
    velocity_noise_mps: float = 1e-3
    """Error of a reported velocity along the normal (m/s): the contact is detected at a substep, so the
    line of centres is exact but the velocities carry about one substep of thrust."""
    min_normal_speed_mps: float = 0.01
    """Slower approaches (m/s, along the normal) are not used: their ratio is noise."""
    use_mass_ratio: bool = False
    """Let the contact inverse use the estimated mass ratio once its std is below ``mass_ratio_max_std``."""
    mass_ratio_max_std: float = 0.02
    """The std (relative) below which an estimated mass ratio is used (with ``use_mass_ratio``)."""
    significance: float | None = None
    """k of the significance test (standard errors, see the module docstring): a pair's (or the pooled)
    estimate replaces the file's restitution only when it differs from it by more than k standard errors;
    None uses every estimate as soon as it exists."""

    def __post_init__(self) -> None:
        for name in ("restitution_prior_std", "mass_ratio_prior_std", "velocity_noise_mps", "min_normal_speed_mps",
                     "mass_ratio_max_std"):
            check_number(self, name, PlannerError, low=0)
        check_flag(self, "use_mass_ratio", PlannerError)
        check_number(self, "significance", PlannerError, low=0, low_open=True, none="off")


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
        self.decisions: dict[tuple[str, str], Significance] = {}  # with the significance test on
        self.pooled_decision = Significance(self.restitution, math.inf, 0.0, 0, False)

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

    def in_use(self, robot: str, obj: str) -> bool:
        """Does the contact inverse use the pair's (or the pooled) estimate? Always once there is one with
        the significance test off; with it on, when the test says the data differ from the file's value."""
        if self.config.significance is None:
            return self.estimate(robot, obj).count > 0
        return (self.decisions.get((robot, obj)) or self.pooled_decision).in_use

    def restitution_for(self, robot: str, obj: str) -> float:
        """The restitution the contact inverse uses for the pair: its estimate, or with the significance test
        on and not passed, the scenario file's."""
        if self.config.significance is not None and not self.in_use(robot, obj):
            return float(np.clip(self.restitution, 0.0, 1.0))
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
            if c.significance is not None:
                self._decide(key)
        return used

    def _decide(self, key: tuple[str, str]) -> None:
        """Re-run the significance test for the pair ``key`` and for the pooled estimate."""
        def test(ms: list[ImpactMeasurement]) -> Significance:
            return significance_test([m.restitution for m in ms], [m.test_variance for m in ms],
                                     self.restitution, self.config.significance)

        self.decisions[key] = test([m for m in self.measurements if (m.robot, m.object) == key])
        self.pooled_decision = test(self.measurements)

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
        if self.config.significance is None:
            ratio_prior = self.mass_ratio(robot, obj).mean
        else:  # the contact inverse's ratio (module docstring)
            m_r, m_o = self.masses_for(robot, obj)
            ratio_prior = m_o / m_r
        vr1_momentum = vr0 - ratio_prior * dvo  # Eq. 5's momentum balance, free of the robot's thrust
        e = float((vo1 - vr1_momentum) @ n) / approach
        sigma = self.config.velocity_noise_mps
        e_var = (sigma * (1.0 + e) / approach) ** 2 + 1e-8
        ratio = -float((vr1 - vr0) @ n) / size
        ratio_var = (sigma * (1.0 + ratio) / size) ** 2 + 1e-8
        return ImpactMeasurement(float(ev["time"]), robot, obj, e, e_var, ratio, ratio_var, approach,
                                 _robot_side_restitution(vr0, vr1, vo0, ratio_prior))

    def report(self) -> dict:
        """JSON-ready estimates: pooled and per pair (mean, std, count); with the significance test on, also
        its verdict (``in_use``, ``z``, the data's mean and its standard error ``test_std``)."""
        def row(est: Estimate, decision: Significance | None) -> dict:
            out = {"mean": est.mean, "std": est.std, "count": est.count}
            if self.config.significance is not None and decision is not None:
                out.update(in_use=decision.in_use, z=decision.z, test_mean=decision.mean,
                           test_std=decision.std_of_mean)
            return out

        return {"restitution": {"pooled": row(self.pooled, self.pooled_decision),
                                **{f"{r}-{o}": row(est, self.decisions.get((r, o)))
                                   for (r, o), est in self.pairs.items()}},
                "mass_ratio": {f"{r}-{o}": row(est, None) for (r, o), est in self.ratios.items()}}


def _robot_side_restitution(vr0: np.ndarray, vr1: np.ndarray, vo0: np.ndarray, ratio: float) -> float | None:
    """Eq. 5 read from the robot alone: the normal from its velocity change, the object's change from momentum
    with ``ratio`` = m_O / m_R (module docstring). None when the robot's change gives no normal."""
    dvr = vr1 - vr0
    size = float(np.linalg.norm(dvr))
    if size < 1e-9 or ratio <= 0:
        return None
    approach = float((vr0 - vo0) @ (-dvr / size))
    if approach <= 1e-9:
        return None
    return -1.0 + (1.0 + ratio) * size / (ratio * approach)
