"""The compiled helpers of the package: load one, or say in one line why the pure-Python path runs instead.

Three small C extensions are built by ``pip install .`` (``setup.py``): ``impact_env.transport._substeps`` (the
impact world's substep loop, action scaling and observation), ``impact_env.tether._substeps`` (the tether
world's kinematic substep loop) and ``impact_env.stl._cmonitor`` (the online STL monitor of the shipped formula
classes). Each is optional: without a C compiler and Python's headers the install still succeeds, the helper is
missing, and the modules that use it run their pure-Python code, which gives the same numbers bit for bit
(``tests/impact_env/transport/test_native_parity.py`` and ``tests/impact_env/tether/test_native_parity.py``
check both paths against each other).
Setting ``IMPACT_ENV_PURE_PYTHON=1`` before the import selects the Python paths on purpose (no note then).
"""

from __future__ import annotations

import importlib
import os
import warnings
from types import ModuleType

PURE_PYTHON_VARIABLE = "IMPACT_ENV_PURE_PYTHON"


def pure_python_requested() -> bool:
    """True when ``IMPACT_ENV_PURE_PYTHON`` is set to anything but ``""`` or ``"0"``."""
    return os.environ.get(PURE_PYTHON_VARIABLE, "") not in ("", "0")


def load(module: str, what: str) -> ModuleType | None:
    """The compiled ``module``, or None with a one-line RuntimeWarning naming ``what`` runs in Python instead."""
    if pure_python_requested():
        return None
    try:
        return importlib.import_module(module)
    except ImportError as error:
        warnings.warn(f"impact_env: {what} runs in pure Python ({module} is not built: {error}; reinstall with a C "
                      "compiler and Python's headers for the fast path): same results, slower", RuntimeWarning,
                      stacklevel=3)
        return None


def chipmunk_addresses(functions: dict[str, str]) -> tuple[int, ...] | None:
    """The addresses of chipmunk's ``functions`` (name -> the C prototype a loop calls it with) in pymunk's cffi
    module, for a C loop that calls chipmunk directly; None if pymunk has no cffi module, its ``cpVect`` or
    ``cpFloat`` is not two doubles or a double, or a function is missing or has another type."""
    try:
        from pymunk._chipmunk import ffi, lib
    except ImportError:  # pragma: no cover - a pymunk build without its cffi module
        return None
    try:
        if ffi.sizeof("cpVect") != 16 or ffi.typeof("cpFloat").cname != "double":
            return None
        out = []
        for name, prototype in functions.items():
            pointer = ffi.addressof(lib, name)
            if ffi.typeof(pointer).cname != prototype:
                return None
            out.append(int(ffi.cast("uintptr_t", pointer)))
        return tuple(out)
    except (AttributeError, TypeError, ffi.error):  # pragma: no cover - pymunk internals moved
        return None
