"""Online identification of the impact model: each pair's restitution (and mass ratio) from observed impacts.

Every robot-object contact the environment reports (both bodies' velocities at first touch and at
separation) is one measurement. The object's velocity change gives the contact normal n exactly (Eq. 6-7),
and along it the point-mass law (Eq. 5) gives

    e = (v_O+ - v_R+) . n / (v_R- - v_O-) . n,        m_O / m_R = -(dv_R . n) / (dv_O . n),

with v_R+ from momentum (the robot thrusts during the contact). Each is a Gaussian estimate per pair, updated
by the conjugate rule, pooled over the pairs until a pair is observed, and the scenario file's value before
any impact. Which value the contact inverse uses is ``IdentificationConfig.estimator``'s: by default
(``bounded``) the file's until the robot's readings, each within the error its thrust limit allows during
the contact (:func:`robot_side_bound`), refute it (:func:`bounded_verdict`): post-impact noise moves only the
object's reading. ``significance`` uses a test at k standard errors (:func:`significance_test`), ``gaussian``
every estimate at once.

Why each step, the estimators' derivations and the measurement that chose the default:
``docs/expert_design.md#identification``.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from impact_env.config_checks import check_choice, check_flag, check_number
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
    robot_side_bound: float = math.inf  # how far the robot's thrust during the contact can put that reading off

    @property
    def robot_side_interval(self) -> tuple[float, float]:
        """The restitutions the robot's reading allows: within ``robot_side_bound`` of it (all of them when
        the robot gave no reading)."""
        if self.restitution_robot_side is None:
            return -math.inf, math.inf
        return self.restitution_robot_side - self.robot_side_bound, self.restitution_robot_side + self.robot_side_bound

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
class Bounded:
    """The bounded estimator's verdict on a set of measurements (``docs/expert_design.md#identification``).

    ``low``, ``high``: the restitutions every robot reading allows (their intervals' intersection; low > high
    when they contradict each other); ``estimate``: the object readings' weighted mean, clipped into
    ``[low, high]``; ``count`` measurements; ``in_use``: the file's restitution lies outside ``[low, high]``
    (the readings refute it), so the estimate replaces it."""

    low: float
    high: float
    estimate: float
    count: int
    in_use: bool


def bounded_verdict(measurements: list[ImpactMeasurement], reference: float) -> Bounded:
    """Do the robot readings of ``measurements`` refute the file's restitution ``reference``? (see
    :class:`Bounded`). None of them, or readings that contradict each other: not in use."""
    low = max((m.robot_side_interval[0] for m in measurements), default=-math.inf)
    high = min((m.robot_side_interval[1] for m in measurements), default=math.inf)
    if not measurements:
        return Bounded(low, high, reference, 0, False)
    w = np.array([1.0 / m.restitution_variance for m in measurements])
    mean = float(w @ np.array([m.restitution for m in measurements]) / w.sum())
    consistent = low <= high
    estimate = float(np.clip(mean, low, high)) if consistent else reference
    return Bounded(low, high, estimate, len(measurements), bool(consistent and not low <= reference <= high))


ESTIMATORS = ("bounded", "significance", "gaussian")
DEFAULT_SIGNIFICANCE = 3.0  # k of the significance estimator when none is given


@dataclass(frozen=True)
class IdentificationConfig:
    """Which estimator :class:`ImpactIdentifier` uses, its prior uncertainties and measurement noise.

    The estimator was chosen by measurement (``python -m benchmarks.identification_trials``, the numbers on
    ``docs/expert_design.md#identification``): ``bounded`` keeps the file's restitution under post-impact
    noise in every trial and takes a mismatch of 0.1-0.3 after two noise-free impacts in most.
    """

    estimator: str = "bounded"
    """``bounded``: an estimate replaces the file's restitution when the robot's readings, each within the
    error its thrust limit allows during the contact, refute the file's value (:func:`bounded_verdict`);
    ``significance``: when the data differ from it by more than ``significance`` standard errors
    (:func:`significance_test`); ``gaussian``: every estimate at once (the behaviour before 0.4)."""
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
    """k of the ``significance`` estimator (standard errors); None: 3. Giving a k
    selects ``significance`` (how 0.3 turned the test on); the gaussian estimator takes none."""

    def __post_init__(self) -> None:
        check_choice(self, "estimator", PlannerError, ESTIMATORS)
        for name in ("restitution_prior_std", "mass_ratio_prior_std", "velocity_noise_mps", "min_normal_speed_mps",
                     "mass_ratio_max_std"):
            check_number(self, name, PlannerError, low=0)
        check_flag(self, "use_mass_ratio", PlannerError)
        check_number(self, "significance", PlannerError, low=0, low_open=True, none="3")
        if self.significance is not None:
            if self.estimator == "gaussian":
                raise PlannerError("IdentificationConfig.significance is the k of estimator='significance'; "
                                   "the gaussian estimator has none (drop significance or change the estimator)")
            object.__setattr__(self, "estimator", "significance")

    @property
    def k(self) -> float:
        """The significance estimator's k (standard errors)."""
        return DEFAULT_SIGNIFICANCE if self.significance is None else float(self.significance)


@dataclass
class ImpactIdentifier:
    """Estimates of restitution and mass ratio per (robot, object) pair, from ``info["impacts"]`` events.

    Args:
        restitution: the scenario file's restitution (the prior mean).
        masses: body name -> mass (kg) from the scenario file (the mass-ratio prior).
        robots, objects: names of the robots and objects (which reported contacts are robot-object).
        accelerations: robot name -> the largest acceleration its thrust limits give (m/s^2, the thrust box's
            diagonal over the mass): how far its thrust can move its velocity during a contact, which bounds
            its reading (the bounded estimator; a robot not given has no bound, so never refutes).
    """

    restitution: float
    masses: dict[str, float]
    robots: frozenset[str]
    objects: frozenset[str]
    config: IdentificationConfig = field(default_factory=IdentificationConfig)
    accelerations: dict[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        c = self.config
        self.pooled = Estimate(self.restitution, c.restitution_prior_std ** 2)
        self.pairs: dict[tuple[str, str], Estimate] = {}
        self.ratios: dict[tuple[str, str], Estimate] = {}
        self.measurements: list[ImpactMeasurement] = []
        self._recent: list[dict] = []  # the contacts reported in the previous call
        self.decisions: dict[tuple[str, str], Significance | Bounded] = {}  # the significance or bounded verdicts
        self.pooled_decision: Significance | Bounded = (
            Bounded(-math.inf, math.inf, self.restitution, 0, False) if self.config.estimator == "bounded"
            else Significance(self.restitution, math.inf, 0.0, 0, False))

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

    def verdict(self, robot: str, obj: str) -> Significance | Bounded | None:
        """The pair's verdict (the pooled one if it has not been observed); None for the gaussian estimator."""
        if self.config.estimator == "gaussian":
            return None
        return self.decisions.get((robot, obj)) or self.pooled_decision

    def in_use(self, robot: str, obj: str) -> bool:
        """Does the contact inverse use the pair's (or the pooled) estimate? With the gaussian estimator once
        there is one; else when the verdict says the data refute the file's value."""
        verdict = self.verdict(robot, obj)
        if verdict is None:
            return self.estimate(robot, obj).count > 0
        return verdict.in_use

    def restitution_for(self, robot: str, obj: str) -> float:
        """The restitution the contact inverse uses for the pair: the scenario file's until the verdict says
        otherwise (gaussian: the estimate at once); then the gaussian estimate (significance) or the bounded
        verdict's estimate."""
        verdict = self.verdict(robot, obj)
        if verdict is None:
            return float(np.clip(self.estimate(robot, obj).mean, 0.0, 1.0))
        if not verdict.in_use:
            return float(np.clip(self.restitution, 0.0, 1.0))
        if isinstance(verdict, Bounded):
            return float(np.clip(verdict.estimate, 0.0, 1.0))
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
        seen = self._recent + list(events)
        for ev in events:
            pair = {ev["a"], ev["b"]}
            robot = next(iter(pair & self.robots), None)
            obj = next(iter(pair & self.objects), None)
            if robot is None or obj is None:
                continue
            m = self._measure(ev, robot, obj)
            if m is None:
                continue
            if any(other is not ev and _overlap(ev, other) for other in seen):
                # another contact of the robot or the object during this one: its impulse is in the robot's
                # velocity change too (or in the object's, and the normal is not this contact's), so the robot's
                # reading cannot refute anything (the object's is kept, as before 0.4)
                m = dataclasses.replace(m, restitution_robot_side=None, robot_side_bound=math.inf)
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
            if c.estimator != "gaussian":
                self._decide(key)
        self._recent = list(events)  # a contact can overlap one reported a step earlier
        return used

    def _decide(self, key: tuple[str, str]) -> None:
        """Re-run the verdict for the pair ``key`` and for the pooled estimate."""
        def test(ms: list[ImpactMeasurement]) -> Significance | Bounded:
            if self.config.estimator == "bounded":
                return bounded_verdict(ms, self.restitution)
            return significance_test([m.restitution for m in ms], [m.test_variance for m in ms],
                                     self.restitution, self.config.k)

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
        if self.config.estimator == "gaussian":
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
        reach = self.accelerations.get(robot, math.inf) * float(ev.get("duration", math.inf))
        return ImpactMeasurement(float(ev["time"]), robot, obj, e, e_var, ratio, ratio_var, approach,
                                 _robot_side_restitution(vr0, vr1, vo0, ratio_prior),
                                 robot_side_bound(vr0, vr1, vo0, ratio_prior, reach))

    def report(self) -> dict:
        """JSON-ready estimates: pooled and per pair (mean, std, count); with the significance estimator also
        its verdict (``in_use``, ``z``, the data's mean and its standard error ``test_std``), with the bounded
        one its verdict (``in_use``, the interval ``low``, ``high`` the robot readings allow, ``estimate``)."""
        def row(est: Estimate, decision: Significance | Bounded | None) -> dict:
            out = {"mean": est.mean, "std": est.std, "count": est.count}
            if isinstance(decision, Significance):
                out.update(in_use=decision.in_use, z=decision.z, test_mean=decision.mean,
                           test_std=decision.std_of_mean)
            elif isinstance(decision, Bounded):
                out.update(in_use=decision.in_use, low=decision.low, high=decision.high, estimate=decision.estimate)
            return out

        gaussian = self.config.estimator == "gaussian"
        return {"restitution": {"pooled": row(self.pooled, None if gaussian else self.pooled_decision),
                                **{f"{r}-{o}": row(est, self.decisions.get((r, o)))
                                   for (r, o), est in self.pairs.items()}},
                "mass_ratio": {f"{r}-{o}": row(est, None) for (r, o), est in self.ratios.items()}}


def _overlap(ev: dict, other: dict) -> bool:
    """Do two reported contacts share a body and overlap in time (first touch to separation)?"""
    if not {ev["a"], ev["b"]} & {other["a"], other["b"]}:
        return False
    start, end = float(ev["time"]), float(ev["time"]) + float(ev.get("duration", 0.0))
    other_start = float(other["time"])
    return other_start <= end + 1e-9 and start <= other_start + float(other.get("duration", 0.0)) + 1e-9


_BOUND_DIRECTIONS = np.array([[math.cos(a), math.sin(a)] for a in np.linspace(0, 2 * math.pi, 16, endpoint=False)])
_BOUND_SLACK = 1.05  # the circle's 16 samples find the largest change of a smooth reading to within 2 %


def robot_side_bound(vr0: np.ndarray, vr1: np.ndarray, vo0: np.ndarray, ratio: float, reach_mps: float) -> float:
    """How far the robot's reading (:func:`_robot_side_restitution`) can be from what its velocity change
    would say without thrust, when the thrust moved the robot's velocity by at most ``reach_mps`` during the
    contact: the largest change of the reading over velocity errors of that size (16 directions, with 5 %
    slack); inf when such an error can make the reading undefined or no reach is known."""
    base = _robot_side_restitution(vr0, vr1, vo0, ratio)
    if base is None or not math.isfinite(reach_mps):
        return math.inf
    worst = 0.0
    for eps in _BOUND_DIRECTIONS * reach_mps:
        other = _robot_side_restitution(vr0, vr1 + eps, vo0, ratio)
        if other is None:
            return math.inf
        worst = max(worst, abs(other - base))
    return _BOUND_SLACK * worst


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
