"""The invariant every fuzzer asserts, and its bookkeeping.

Every input either works or raises one of the package's typed errors (:data:`ACCEPTED`: exactly
``impact_env.errors.TYPED_ERRORS`` and ``planners.errors.PLANNER_ERRORS``), within :data:`DEADLINE_S` seconds
of CPU time; and what works produces no NaN or inf and keeps every body inside the world. Anything else
(another exception, a hang, a NaN, a body outside) fails the test, and hypothesis shrinks it to a small
input.

The deadline is CPU time of this process (``ITIMER_PROF``), not wall clock: it does not fire because the
machine is busy, it does fire on a loop that never ends, and it leaves pytest-timeout's wall-clock alarm
(``ITIMER_REAL``) alone.
"""

from __future__ import annotations

import contextlib
import math
import signal
import threading
from collections import Counter
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np

from impact_env.errors import TYPED_ERRORS
from planners.errors import PLANNER_ERRORS

ACCEPTED: tuple[type[Exception], ...] = TYPED_ERRORS + PLANNER_ERRORS
DEADLINE_S = 10.0
# fuzzer -> Counter: inputs (examples drawn), and the outcomes of their checks: one input can be checked
# several ways (an STL text is parsed, evaluated on a trace and used as a task), each "worked" or "rejected"
COUNTS: dict[str, Counter] = {}


class InputTimeout(AssertionError):
    """An input took longer than DEADLINE_S of CPU time: a hang as far as the fuzzers are concerned."""


@contextlib.contextmanager
def cpu_deadline(seconds: float = DEADLINE_S) -> Iterator[None]:
    if threading.current_thread() is not threading.main_thread():  # signals reach the main thread only
        yield
        return

    def expired(signum: int, frame: Any) -> None:
        raise InputTimeout(f"input still running after {seconds} s of CPU time")

    previous = signal.signal(signal.SIGPROF, expired)
    signal.setitimer(signal.ITIMER_PROF, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_PROF, 0.0)
        signal.signal(signal.SIGPROF, previous)


def attempt(fuzzer: str, fn: Callable[[], Any]) -> Any | None:
    """Run ``fn`` under the deadline: its result, or None if it raised an accepted typed error."""
    counts = COUNTS.setdefault(fuzzer, Counter())
    with cpu_deadline():
        try:
            result = fn()
        except ACCEPTED as exc:
            assert str(exc), f"{type(exc).__name__} without a message"
            counts["rejected"] += 1
            return None
    counts["worked"] += 1
    return result


def assert_finite(value: Any, what: str) -> None:
    array = np.asarray(value, dtype=float)
    assert np.all(np.isfinite(array)), f"{what} is not finite: {value!r}"


def assert_inside(env: Any) -> None:
    """Every body's centre inside the world box (contacts keep discs off the walls up to a tiny slop)."""
    core = env.unwrapped.core if hasattr(env, "unwrapped") else env.core
    xmin, xmax, ymin, ymax = core.scenario.world_box
    for name, state in zip(core.body_names, core._state):
        assert_finite(state, f"state of {name}")
        x, y = state[0], state[1]
        assert xmin - 1e-6 <= x <= xmax + 1e-6 and ymin - 1e-6 <= y <= ymax + 1e-6, \
            f"{name} at ({x}, {y}) is outside the world box {core.scenario.world_box}"


def fly(env: Any, steps: int, seed: int = 0) -> None:
    """Reset and step a Gymnasium env with extreme and random actions, checking the invariant every step."""
    obs, info = env.reset(seed=seed)
    assert_finite(obs, "observation at reset")
    assert math.isfinite(info["robustness"])
    rng = np.random.default_rng(seed)
    n = env.action_space.shape[0]
    for k in range(steps):
        action = [np.ones(n), -np.ones(n), rng.uniform(-1, 1, n), np.zeros(n)][k % 4]
        obs, reward, terminated, truncated, info = env.step(action.astype(np.float32))
        assert_finite(obs, "observation")
        assert math.isfinite(reward), f"reward {reward}"
        assert math.isfinite(info["robustness"]) and math.isfinite(info["fuel_Ns"])
        assert_inside(env)
        if terminated or truncated:
            break
