"""The impact world's per-step kernels in C (``_substeps.c``): one call runs a control period's substeps, others
scale the action, write the observations and build the PettingZoo env's per-agent dicts (from row views of one
new array); None here means the pure-Python path runs (the same numbers and dicts, slower).

Why this design. At the corridor's size chipmunk's own ``cpSpaceStep`` is a tenth of an env step; the rest was
Python driving it (angle, sin/cos, force and torque per robot and substep). So the loop goes to C and calls
chipmunk itself, through the function pointers pymunk's cffi module already exposes (``ffi.addressof(lib,
"cpSpaceStep")``): pymunk links chipmunk statically into that module and ships no library or header to link
against, and a pointer taken at run time works with any pymunk 7 build whose prototypes match (checked below:
a mismatch means the Python path). The extension is plain C against Python's headers (no cffi or numba at
build time; numba would add llvmlite, ~40 MB, and a JIT warm-up to the base install for the same loop), built
by ``setup.py`` as an optional extension: no compiler, no helper, a one-line note (:mod:`impact_env.native`).
The contact callbacks stay pymunk's Python callbacks, called by chipmunk with the GIL held; the loop stops after
any substep in which a contact ended, so that the World closes it in Python in its fixed order before the next.
Flags: no fused multiply-add and no sin/cos builtins, so every product and libm call is the Python path's.
"""

from __future__ import annotations

from typing import Any

from impact_env.native import chipmunk_addresses, load

_substeps = load("impact_env.transport._substeps", "the impact world's substep loop")

try:
    from pymunk._chipmunk import ffi as _ffi
except ImportError:  # pragma: no cover - a pymunk build without its cffi module
    _ffi = None

# name -> the prototype the C loop calls it with (cpFloat is double in pymunk's build); the order of _substeps.c
CHIPMUNK_FUNCTIONS = {
    "cpSpaceStep": "void(*)(struct cpSpace *, double)",
    "cpBodyGetAngle": "double(*)(struct cpBody *)",
    "cpBodySetForce": "void(*)(struct cpBody *, struct cpVect)",
    "cpBodySetTorque": "void(*)(struct cpBody *, double)",
    "cpBodyGetPosition": "struct cpVect(*)(struct cpBody *)",
    "cpBodyGetVelocity": "struct cpVect(*)(struct cpBody *)",
    "cpBodyGetAngularVelocity": "double(*)(struct cpBody *)",
}


def _chipmunk_addresses() -> tuple[int, ...] | None:
    """The addresses of CHIPMUNK_FUNCTIONS in pymunk's module, or None if one is missing or has another type."""
    if _ffi is None or _substeps is None:
        return None
    return chipmunk_addresses(CHIPMUNK_FUNCTIONS)


_ADDRESSES = _chipmunk_addresses()
_loop_module = _substeps if _ADDRESSES is not None else None  # built, and matching this pymunk
# the per-step kernels around the loop (None: the callers' Python paths); see _substeps.c for each
Observer = _loop_module.Observer if _loop_module is not None else None
parallel_outputs = _loop_module.parallel_outputs if _loop_module is not None else None


def available() -> bool:
    """True when the compiled loop is built and matches this pymunk."""
    return _ADDRESSES is not None


def substep_loop(space: Any, bodies: list[Any], n_robots: int, dt_s: float, separated: list, wrench: Any,
                 limits: Any) -> Any:
    """A ``SubstepLoop`` over a pymunk Space and its bodies (scenario order, robots first), or None.

    ``wrench`` is the (n_robots, 3) float64 array it reads the body-frame wrenches from (and its ``set_action``
    writes, scaled by ``limits``, the same shape); ``separated`` the World's list that the separate callback
    appends to (a non-empty list ends a ``run``).
    """
    if _ADDRESSES is None or _loop_module is None:
        return None
    try:
        space_address = int(_ffi.cast("uintptr_t", space._space))
        body_addresses = [int(_ffi.cast("uintptr_t", b._body)) for b in bodies]
    except AttributeError:  # pragma: no cover - pymunk internals moved: the Python path
        return None
    return _loop_module.SubstepLoop(_ADDRESSES, space_address, body_addresses, n_robots, dt_s, space, separated, wrench,
                                  limits)
