"""Reading actions: whatever a caller passes becomes plain numbers of the documented shape, or an ActionError.

Both transport environments accept an array-like of numbers (a numpy array of an integer or float dtype, or
nested lists and tuples of Python numbers). Strings, booleans, None, dicts, ragged lists, masked arrays with
masked entries and any other shape than the documented ones are refused with a message naming the shape that
would be accepted, rather than silently reinterpreted (a (3, 2) array holds six numbers, but not the (2, 3) =
two robots times (Fx, Fy, torque)).
"""

from __future__ import annotations

import numbers
from collections.abc import Mapping

import numpy as np

from impact_env.errors import ActionError, brief

_NUMERIC_KINDS = "iuf"  # signed and unsigned integers, floats (not bool, complex, strings, objects)


def _brief(value: object) -> str:
    return brief(value, width=80)


def is_masked(action: object) -> bool:
    """Whether ``action`` is a numpy masked array or a list or tuple holding one: the compiled paths would read
    its data under the mask, so such actions take :func:`numbers_of`."""
    if isinstance(action, np.ma.MaskedArray):
        return True
    return (type(action) is list or type(action) is tuple) and any(isinstance(row, np.ma.MaskedArray) for row in action)


def numbers_of(action: object, shapes: tuple[tuple[int, ...], ...], what: str, layout: str) -> list[float]:
    """The numbers of ``action`` in row-major order if its shape is one of ``shapes``; else ActionError.

    ``what`` names the action in messages (``"action"``, ``"actions['R1']"``) and ``layout`` says what the
    numbers are (``"Fx, Fy, torque per robot"``). Finiteness is checked by the caller.
    """
    expected = " or ".join(str(s) for s in shapes)
    count = int(np.prod(shapes[0]))
    if isinstance(action, (list, tuple)) and any(isinstance(row, np.ma.MaskedArray) for row in action):
        action = np.ma.stack(action) if all(isinstance(row, np.ndarray) for row in action) else list(action)
    if isinstance(action, np.ma.MaskedArray):
        if np.ma.is_masked(action):  # a masked entry is no number (tolist() would make it None)
            raise ActionError(f"{what} is a masked array with {int(np.ma.count_masked(action))} masked entries; "
                              f"pass {count} plain numbers ({layout}), e.g. action.filled(0.0)")
        action = np.ma.getdata(action)
    if isinstance(action, np.ndarray) and type(action) is not np.ndarray:  # np.matrix and other subclasses
        action = np.asarray(action)
    if isinstance(action, np.ndarray) and action.dtype.kind in _NUMERIC_KINDS:
        array = action
    else:
        if action is None or isinstance(action, (str, bytes, bytearray, Mapping, set, frozenset, bool)):
            raise ActionError(f"{what} must be {count} numbers ({layout}) of shape {expected}, got "
                              f"{type(action).__name__} {_brief(action)}")
        try:
            array = np.asarray(action)
        except (ValueError, TypeError, RecursionError):  # ragged nesting, e.g. [[1, 2, 3], [4, 5]]; too deep
            raise ActionError(f"{what} must be a rectangular array of numbers ({layout}) of shape {expected}; "
                              f"got {_brief(action)}, which is ragged or nested too deeply") from None
        if array.dtype.kind == "O":  # Python ints too large for int64, or mixed objects
            flat = array.reshape(-1).tolist()
            if not all(isinstance(x, numbers.Real) and not isinstance(x, bool) for x in flat):
                raise ActionError(f"{what} must contain only numbers ({layout}), got {_brief(action)}")
            try:
                array = np.array(flat, dtype=float).reshape(array.shape)
            except OverflowError:
                raise ActionError(f"{what} contains an integer too large for a float: {_brief(action)}") from None
        elif array.dtype.kind not in _NUMERIC_KINDS:
            raise ActionError(f"{what} must contain only numbers ({layout}), got dtype {array.dtype} in "
                              f"{_brief(action)}")
    if array.shape not in shapes:
        raise ActionError(f"{what} must be {count} numbers ({layout}) of shape {expected}, got shape {array.shape}")
    return array.reshape(-1).tolist()
