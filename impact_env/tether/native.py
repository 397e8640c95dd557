"""The tether world's kinematic substep loop in C (``_substeps.c``); None here means the Python loop runs (the
same trajectories, slower).

Why this design. At ``kinematic`` fidelity every substep integrates Eq. (5) by one RK4 step (four evaluations of
a unit vector per tether) before chipmunk steps; in Python that was two thirds of an env step. The loop goes to
C as the impact world's does (:mod:`impact_env.transport.native`): chipmunk is called through the function
pointers pymunk's cffi module exposes, checked against the prototypes below at import. It takes the substeps
that need nothing but arithmetic and hands back to :class:`~impact_env.tether.physics.TetherWorld` for the rest:
the wall test (numpy, about one substep in sixty), the tether checks and attachments (when their cached budget
runs out) and a cargo exactly at an anchor (where Python raises). Bit for bit: no fused multiply-add, and
``math.hypot`` done as CPython does it (its own compensated algorithm, not libm's), which is why the loop is used
only on CPython 3.11 and later (3.10 has an older algorithm) and only if its hypot agrees with ``math.hypot`` on
a sample at import. ``tests/impact_env/tether/test_native_parity.py`` flies whole episodes through both loops.
"""

from __future__ import annotations

import contextlib
import math
import random
import sys
from collections.abc import Iterator
from typing import Any

from impact_env.native import chipmunk_addresses, load

_substeps = load("impact_env.tether._substeps", "the tether world's kinematic substep loop")

try:
    from pymunk._chipmunk import ffi as _ffi
except ImportError:  # pragma: no cover - a pymunk build without its cffi module
    _ffi = None

# name -> the prototype the C loop calls it with (cpFloat is double in pymunk's build); the order of _substeps.c
CHIPMUNK_FUNCTIONS = {
    "cpSpaceStep": "void(*)(struct cpSpace *, double)",
    "cpBodyGetPosition": "struct cpVect(*)(struct cpBody *)",
    "cpBodySetVelocity": "void(*)(struct cpBody *, struct cpVect)",
}


def hypot_sample(n: int = 4000, seed: int = 0) -> list[tuple[float, float]]:
    """Pairs the loop's hypot is checked on: station-sized differences, tiny and huge ones, zeros, subnormals."""
    rng = random.Random(seed)
    pairs = [(0.0, 0.0), (-0.0, 3.0), (5e-324, 0.0), (3e-310, -4e-310), (1e300, 1e300), (3.0, 4.0)]
    for _ in range(n):
        scale = 10.0 ** rng.uniform(-12, 4)
        pairs.append((rng.uniform(-1, 1) * scale, rng.uniform(-1, 1) * scale * rng.choice((1.0, 1e-3, 1e3))))
    return pairs


def _hypot_agrees() -> bool:
    assert _substeps is not None  # checked by the caller
    return all(_substeps.hypot(x, y) == math.hypot(x, y) for x, y in hypot_sample())


def _chipmunk_addresses() -> tuple[int, ...] | None:
    """The addresses of CHIPMUNK_FUNCTIONS in pymunk's module, or None if the loop cannot be used here."""
    if _ffi is None or _substeps is None or sys.version_info < (3, 11) or not _hypot_agrees():
        return None
    return chipmunk_addresses(CHIPMUNK_FUNCTIONS)


_ADDRESSES = _chipmunk_addresses()


def available() -> bool:
    """True when the compiled loop is built and usable with this Python and pymunk."""
    return _ADDRESSES is not None


@contextlib.contextmanager
def disabled() -> Iterator[None]:
    """Worlds built inside run the Python loop, as in a build without the compiled one (benchmarks and tests
    compare the two). Not thread-safe: it switches the module's state."""
    global _ADDRESSES
    saved, _ADDRESSES = _ADDRESSES, None
    try:
        yield
    finally:
        _ADDRESSES = saved


def kinematic_loop(space: Any, body: Any, dt_s: float, winch_N: float) -> Any:
    """A ``KinematicLoop`` over a pymunk Space and its cargo body, or None (the Python loop runs)."""
    if _ADDRESSES is None:
        return None
    try:
        space_address = int(_ffi.cast("uintptr_t", space._space))
        body_address = int(_ffi.cast("uintptr_t", body._body))
    except AttributeError:  # pragma: no cover - pymunk internals moved: the Python path
        return None
    assert _substeps is not None  # _ADDRESSES is None without it
    return _substeps.KinematicLoop(_ADDRESSES, space_address, body_address, dt_s, winch_N, space)
