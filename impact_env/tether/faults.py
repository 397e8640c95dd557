"""Faults of the tether fleet, injected into an episode from its reset seed: the environments' ``faults=`` option.

Four kinds, each what a real station would throw at the expert:

- an **anchor that fails**: it lets go of the tether pulling on it (event ``anchor_failed``), or, when no
  tether pulls at that moment, refuses the next attachment (event ``refused`` when the tether would start);
  a failed anchor refuses every later attachment;
- a **tether that snaps** (event ``snapped``): the robot lets go and may attach again;
- a **robot that drops out** (event ``dropped_out``): it lets go and accepts no attach command any more;
- a **winch speed error**: each robot's winch reels at ``w (1 +- e)``, ``e`` drawn per robot.

The times of the first three are drawn uniformly in ``window_s``, and which tether or robot they hit from the
same generator, at reset, after the start position: the same seed gives the same faults, and an episode without
faults draws nothing (its trajectories are those of an environment without the option).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from impact_env.config_checks import check_integer, fail
from impact_env.errors import EnvConfigError

MAX_FAULTS = 100  # of each kind per episode


@dataclass(frozen=True)
class FaultConfig:
    """Which faults an episode gets (see the module docstring); all off by default."""

    anchor_failures: int = 0
    """Anchors that fail in an episode."""
    tether_snaps: int = 0
    """Tethers that snap in an episode."""
    robot_dropouts: int = 0
    """Robots that drop out in an episode (at most all but one)."""
    winch_speed_error: tuple[float, float] | None = None
    """(lo, hi): each robot's winch speed is ``w (1 + s e)`` with ``e`` uniform in [lo, hi] and a random sign
    ``s`` (fractions, 0 <= lo <= hi < 1); None: every winch at ``w``."""
    window_s: tuple[float, float] = (10.0, 150.0)
    """The interval (s) in which the faults' times are drawn, uniformly."""

    def __post_init__(self) -> None:
        for name in ("anchor_failures", "tether_snaps", "robot_dropouts"):
            check_integer(self, name, EnvConfigError, low=0, high=MAX_FAULTS)
        object.__setattr__(self, "window_s", _pair(self, "window_s", 0.0, 1e9))
        if not self.window_s[0] <= self.window_s[1]:
            fail("FaultConfig.window_s", self.window_s, "(t0, t1) with t0 <= t1", EnvConfigError)
        if self.winch_speed_error is not None:
            object.__setattr__(self, "winch_speed_error", _pair(self, "winch_speed_error", 0.0, 0.95))
            lo, hi = self.winch_speed_error
            if not lo <= hi:
                fail("FaultConfig.winch_speed_error", self.winch_speed_error,
                     "None or (lo, hi) with 0 <= lo <= hi < 1", EnvConfigError)

    @property
    def any(self) -> bool:
        return bool(self.anchor_failures or self.tether_snaps or self.robot_dropouts or self.winch_speed_error)

    @classmethod
    def of(cls, value: Any) -> FaultConfig | None:
        """A FaultConfig from the option's value: None, a FaultConfig, or a dict of its fields."""
        if value is None or isinstance(value, FaultConfig):
            return value
        if isinstance(value, dict):
            fields = {"anchor_failures", "tether_snaps", "robot_dropouts", "winch_speed_error", "window_s"}
            unknown = sorted(set(map(str, value)) - fields)
            if unknown:
                raise EnvConfigError(f"faults has no field {unknown[0]!r}; its fields are {', '.join(sorted(fields))}")
            return cls(**value)
        raise EnvConfigError(f"faults must be None, a FaultConfig or a dict of its fields, got "
                             f"{type(value).__name__}")


def parse_faults(text: str | None) -> dict[str, Any] | None:
    """The ``--faults`` option: ``anchor_failures=1,winch_speed_error=0.1:0.3`` as FaultConfig's fields (a pair
    is written ``lo:hi``); None or an empty text is no faults."""
    if text is None or not text.strip():
        return None
    out: dict[str, Any] = {}
    for part in text.split(","):
        key, eq, value = part.partition("=")
        key = key.strip()
        if not eq:
            raise EnvConfigError(f"--faults: {part!r} is not FIELD=VALUE (e.g. anchor_failures=1)")
        try:
            if ":" in value:
                lo, hi = value.split(":", 1)
                out[key] = (float(lo), float(hi))
            else:
                out[key] = int(value) if value.strip().lstrip("+").isdigit() else float(value)
        except ValueError:
            raise EnvConfigError(f"--faults: {key} = {value!r} is not a number (or lo:hi)") from None
    FaultConfig.of(out)  # unknown fields and bad values, named, before any env is built
    return out


def _pair(config: FaultConfig, name: str, low: float, high: float) -> tuple[float, float]:
    value = getattr(config, name)
    try:
        pair = tuple(value)
    except TypeError:
        pair = ()
    ok = len(pair) == 2 and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in pair)
    if not ok or not all(low <= float(v) <= high for v in pair):
        fail(f"FaultConfig.{name}", value, f"a pair (lo, hi) of numbers in [{low:g}, {high:g}]", EnvConfigError)
    return (float(pair[0]), float(pair[1]))


@dataclass
class FaultSchedule:
    """One episode's draws: per fault ``(time_s, kind, pick)``, ``pick`` in [0, 1) choosing what it hits, in time
    order; and each robot's winch speed factor."""

    events: list[tuple[float, str, float]]
    winch_factors: tuple[float, ...]

    @classmethod
    def draw(cls, faults: FaultConfig | None, n_robots: int, rng: np.random.Generator) -> FaultSchedule:
        if faults is None or not faults.any:
            return cls([], (1.0,) * n_robots)
        if faults.robot_dropouts >= n_robots:
            raise EnvConfigError(f"FaultConfig.robot_dropouts must be < the station's {n_robots} robots, got "
                                 f"{faults.robot_dropouts}")
        t0, t1 = faults.window_s
        events = []
        for kind, count in (("anchor", faults.anchor_failures), ("snap", faults.tether_snaps),
                            ("dropout", faults.robot_dropouts)):
            for _ in range(count):
                events.append((float(rng.uniform(t0, t1)), kind, float(rng.uniform())))
        factors = (1.0,) * n_robots
        if faults.winch_speed_error is not None:
            lo, hi = faults.winch_speed_error
            factors = tuple(float(1.0 + rng.choice((-1.0, 1.0)) * rng.uniform(lo, hi)) for _ in range(n_robots))
        return cls(sorted(events), factors)
