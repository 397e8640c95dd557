"""Checks of configuration fields: the one place that says what "a finite number", "an integer >= 1" or "one of
a, b" means, for every ``*Config`` of impact_env, planners and baselines.

A config validates itself in ``__post_init__`` by calling these with itself, the field's name and its layer's
typed error (:class:`~impact_env.errors.EnvConfigError` or :class:`~impact_env.errors.EngineError` here,
:class:`~planners.errors.PlannerError` and its subclasses in planners, ``ImpactEnvError`` in baselines). A bad
value raises that error with a message naming the class and the field and saying what is allowed::

    MissionConfig.reach_tolerance_m must be a finite number >= 0, got -1
    PlannerConfig.intervals must be None (the scenario's hint, else 10) or an integer >= 2, got 1.5

``none`` says that None is allowed and what it means; :func:`brief` is a value's repr as messages show it;
:func:`moved_into` keeps a deprecated keyword working. The convention: ``docs/contributing.md``.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import warnings
from collections.abc import Callable, Iterable
from typing import Any, NoReturn

__all__ = ["NOT_GIVEN", "brief", "check_choice", "check_flag", "check_instance", "check_integer", "check_number",
           "check_text", "check_value", "fail", "is_finite_number", "moved_into", "number_rule", "warn_deprecated"]


def brief(value: Any, width: int = 60) -> str:
    """``repr(value)``, cut to ``width`` characters (an integer of thousands of digits or a list nested
    thousands deep cannot be shown: then its type)."""
    try:
        text = repr(value)
    except (ValueError, RecursionError):
        return f"a {type(value).__name__}"
    return text if len(text) <= width else text[:width - 3] + "..."


def is_finite_number(value: Any) -> bool:
    """A real number (numpy's included) that is finite: not a bool, not NaN or infinite, not an integer too
    large for a float."""
    if type(value) is float:  # the common case, without the ABC check (the controllers ask every step)
        return math.isfinite(value)
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        return False
    try:
        return math.isfinite(value)
    except OverflowError:
        return False


def number_rule(low: float | None = None, high: float | None = None, low_open: bool = False,
                integer: bool = False) -> str:
    """What a number must be, in words: ``"a finite number > 0"``, ``"an integer >= 1"``, ``"a finite number
    in (0, 1]"``."""
    what = "an integer" if integer else "a finite number"
    if low is not None and high is not None:
        return f"{what} in {'(' if low_open else '['}{_number(low)}, {_number(high)}]"
    if low is not None:
        return f"{what} {'>' if low_open else '>='} {_number(low)}"
    if high is not None:
        return f"{what} <= {_number(high)}"
    return what


def _number(x: float) -> str:
    return str(int(x)) if float(x).is_integer() and abs(x) < 1e15 else f"{x:g}"


def _allowed(rule: str, none: str | None) -> str:
    if none is None:
        return rule
    return f"None ({none}) or {rule}" if none else f"None or {rule}"


def fail(where: str, value: Any, allowed: str, error: type[Exception]) -> NoReturn:
    """Raise ``error("<where> must be <allowed>, got <value>")``."""
    raise error(f"{where} must be {allowed}, got {brief(value)}")


def check_value(where: str, value: Any, error: type[Exception], *, low: float | None = None,
                high: float | None = None, low_open: bool = False, integer: bool = False,
                none: str | None = None) -> None:
    """Raise ``error`` naming ``where`` unless ``value`` is a finite number (an integer with ``integer``)
    within the bounds (``low < value`` with ``low_open``, else ``low <= value``; ``value <= high``), or None
    when ``none`` says what None means."""
    if value is None and none is not None:
        return
    if integer:
        ok = isinstance(value, numbers.Integral) and not isinstance(value, bool)
    else:
        ok = is_finite_number(value)
    if ok and low is not None:
        ok = value > low if low_open else value >= low
    if ok and high is not None:
        ok = value <= high
    if not ok:
        fail(where, value, _allowed(number_rule(low, high, low_open, integer), none), error)


def _where(config: Any, name: str) -> str:
    return f"{type(config).__name__}.{name}"


def check_number(config: Any, name: str, error: type[Exception], *, low: float | None = None,
                 high: float | None = None, low_open: bool = False, none: str | None = None) -> None:
    """``config.<name>`` is a finite number within the bounds (see :func:`check_value`)."""
    check_value(_where(config, name), getattr(config, name), error, low=low, high=high, low_open=low_open,
                none=none)


def check_integer(config: Any, name: str, error: type[Exception], *, low: int | None = None,
                  high: int | None = None, none: str | None = None) -> None:
    """``config.<name>`` is an integer (not a bool) within the bounds."""
    check_value(_where(config, name), getattr(config, name), error, low=low, high=high, integer=True, none=none)


def check_flag(config: Any, name: str, error: type[Exception]) -> None:
    """``config.<name>`` is True or False (not 0, 1 or a string)."""
    value = getattr(config, name)
    if not isinstance(value, bool):
        fail(_where(config, name), value, "True or False", error)


def check_choice(config: Any, name: str, error: type[Exception], choices: Iterable[str], *,
                 none: str | None = None) -> None:
    """``config.<name>`` is one of ``choices`` (or None when ``none`` says what None means)."""
    value = getattr(config, name)
    choices = tuple(choices)
    if value is None and none is not None:
        return
    if not (isinstance(value, str) and value in choices):
        fail(_where(config, name), value, _allowed(f"one of {', '.join(choices)}", none), error)


def check_text(config: Any, name: str, error: type[Exception], *, none: str | None = None) -> None:
    """``config.<name>`` is a non-empty string (a name, a path), or None when ``none`` says what None means."""
    value = getattr(config, name)
    if value is None and none is not None:
        return
    if not (isinstance(value, str) and value):
        fail(_where(config, name), value, _allowed("a non-empty string", none), error)


def check_widths(config: Any, name: str, error: type[Exception], *, lists: bool = False) -> None:
    """``config.<name>`` is a non-empty tuple (or, with ``lists``, a list) of integers >= 1: a network's hidden
    layer widths."""
    value = getattr(config, name)
    kinds = (tuple, list) if lists else tuple
    if not (isinstance(value, kinds) and len(value) > 0
            and all(isinstance(w, int) and not isinstance(w, bool) and w >= 1 for w in value)):
        fail(_where(config, name), value, "a non-empty tuple of integers >= 1 (layer widths)", error)


def check_instance(config: Any, name: str, error: type[Exception], kind: type | tuple[type, ...] | Callable, *,
                   what: str, none: str | None = None) -> None:
    """``config.<name>`` is an instance of ``kind`` (``what`` says it in words, e.g. ``"a SolverOptions"``), or
    None when ``none`` says what None means. ``kind`` may be ``callable``: then any callable passes."""
    value = getattr(config, name)
    if value is None and none is not None:
        return
    # kind is a class or a tuple of classes wherever isinstance sees it (callable is taken first)
    ok = callable(value) if kind is callable else isinstance(value, kind)  # type: ignore[arg-type]
    if not ok:
        fail(_where(config, name), value, _allowed(what, none), error)


class _NotGiven:
    """The default of a deprecated constructor keyword: tells "not given" from every value, None included."""

    def __repr__(self) -> str:
        return "NOT_GIVEN"


NOT_GIVEN: Any = _NotGiven()


def warn_deprecated(message: str, stacklevel: int = 4) -> None:
    """A ``DeprecationWarning`` with ``message``, pointed at the caller of the config's constructor."""
    warnings.warn(message, DeprecationWarning, stacklevel=stacklevel)


def moved_into(config: Any, field: str, keywords: dict[str, Any], error: type[Exception]) -> None:
    """Deprecated constructor keywords that now live in the nested config ``config.<field>`` (given as
    ``InitVar`` keywords defaulting to :data:`NOT_GIVEN`): each given one is warned about and set there.

    ``PlannerConfig(time_limit_s=5)`` becomes ``PlannerConfig(solver_options=SolverOptions(..., time_limit_s=5))``
    with ``DeprecationWarning: PlannerConfig(time_limit_s=...) is deprecated: pass
    PlannerConfig(solver_options=SolverOptions(time_limit_s=...))``; the nested config validates the values."""
    given = {name: value for name, value in keywords.items() if value is not NOT_GIVEN}
    if not given:
        return
    cls, nested = type(config).__name__, getattr(config, field)
    if not dataclasses.is_dataclass(nested):
        fail(f"{cls}.{field}", nested, f"a {type(nested).__name__} to set {', '.join(given)} in", error)
    names = ", ".join(f"{name}=..." for name in given)
    warn_deprecated(f"{cls}({names}) is deprecated and will be removed in 0.4.0: pass "
                    f"{cls}({field}={type(nested).__name__}({names}))", stacklevel=5)
    # nested is the config's own value of the field: a dataclass instance, never a class
    object.__setattr__(config, field, dataclasses.replace(nested, **given))  # type: ignore[type-var]
