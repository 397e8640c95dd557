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
import json
import math
import os
import signal
import threading
import time
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


# ------------------------------------------------------------------------------------ running a fuzzer
def hypothesis_test(name: str, strategy: Any, prop: Callable[[Any], None], max_examples: int,
                    seed_value: int | None = None) -> Callable[[], None]:
    """A hypothesis test of ``prop`` over ``strategy`` that counts its inputs in COUNTS[name]: derandomized
    (the default suite's fixed inputs), or seeded with ``seed_value`` (the long runs' fresh ones)."""
    from hypothesis import HealthCheck, given, seed, settings

    def counted(value: Any) -> None:
        COUNTS.setdefault(name, Counter())["inputs"] += 1
        prop(value)

    test = settings(max_examples=max_examples, deadline=None, database=None, derandomize=seed_value is None,
                    suppress_health_check=list(HealthCheck), print_blob=True)(given(strategy)(counted))
    return test if seed_value is None else seed(seed_value)(test)


def fuzz_fixed(name: str, strategy: Any, prop: Callable[[Any], None], examples: int) -> None:
    """The default suite's run: ``examples`` derandomized inputs, all of them drawn, reported."""
    hypothesis_test(name, strategy, prop, examples)()
    assert COUNTS[name]["inputs"] >= examples
    report(name, COUNTS[name], slow=False)


def fuzz_for_budget(name: str, strategy: Any, prop: Callable[[Any], None], per_round: int) -> None:
    """The slow suite's run: fresh seeds, ``per_round`` inputs a round, for IMPACT_ENV_FUZZ_SECONDS (60 s)."""
    budget = float(os.environ.get("IMPACT_ENV_FUZZ_SECONDS", "60"))
    start = time.monotonic()
    round_ = 0
    while time.monotonic() - start < budget:
        hypothesis_test(name, strategy, prop, per_round, seed_value=int(time.time_ns() % 2 ** 32) + round_)()
        round_ += 1
    report(name, COUNTS[name], slow=True, seconds=time.monotonic() - start)


def report(name: str, counts, slow: bool, seconds: float | None = None) -> None:
    """One JSON line per fuzzer in IMPACT_ENV_FUZZ_REPORT (if set); tests/fuzz/conftest.py prints the table."""
    path = os.environ.get("IMPACT_ENV_FUZZ_REPORT")
    if path:
        with open(path, "a") as f:
            f.write(json.dumps({"fuzzer": name, "slow": slow, "seconds": seconds, **counts}) + "\n")
