"""Reading a task file: where its text comes from, its TOML, and the checks of every field.

Both world families' files (impact scenarios, tether stations) are small TOML documents read the same way:
a shipped name or a path, UTF-8 text, then one table at a time through :class:`Fields`, which hands out
checked values (``kind="float"``, ``"vec2"``, ``"box"``, ...) and reports any key nobody asked for. Every
error is a :class:`~impact_env.errors.ScenarioError` that names the field path, e.g.
``robots[1].radius_m must be > 0, got -0.2``; :func:`with_source` puts the file in front.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

from impact_env import catalogue
from impact_env.errors import ScenarioError, STLError, brief

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

T = TypeVar("T")


# ----------------------------------------------------------------------------------------------- the file


def load_toml(name_or_path: str | Path, kind: str, elsewhere: dict[str, str] | None = None) -> tuple[dict, str]:
    """The parsed document of a shipped file of ``kind`` (by name) or of a TOML file (by path), and its source.

    ``elsewhere`` maps another kind to the message for one of its shipped names given here (``{name!r}`` is
    filled in), e.g. a station's name given to the scenario loader.
    """
    if not isinstance(name_or_path, (str, Path)):
        raise ScenarioError(f"a {kind} is a shipped name or a path to a .toml file, got {type(name_or_path).__name__}")
    text, source = read_source(name_or_path, kind, elsewhere or {})
    try:
        return tomllib.loads(text), source
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{source}: not valid TOML: {exc}") from None
    except (ValueError, RecursionError) as exc:  # an integer of thousands of digits; arrays nested thousands deep
        raise ScenarioError(f"{source}: not a usable TOML file: {str(exc)[:120]}") from None


def read_source(name_or_path: str | Path, kind: str, elsewhere: dict[str, str]) -> tuple[str, str]:
    """(text, source) of a shipped name or a path: the checks of :func:`load_toml` before the TOML."""
    path = Path(name_or_path)
    try:
        is_path = path.suffix == ".toml" or path.exists() or "/" in str(name_or_path)
    except (OSError, ValueError):  # e.g. a NUL byte or a name too long for the file system
        raise ScenarioError(f"{str(name_or_path)[:80]!r} is neither a shipped {kind} nor a readable path") from None
    if is_path:
        if not path.is_file():
            raise ScenarioError(f"{kind} file {str(path)!r} does not exist")
        try:
            raw = path.read_bytes()
        except OSError as exc:
            raise ScenarioError(f"cannot read {kind} file {str(path)!r}: {exc.strerror or exc}") from None
        try:
            return raw.decode("utf-8"), str(path)
        except UnicodeDecodeError as exc:
            line = raw[:exc.start].count(b"\n") + 1
            raise ScenarioError(f"{path}: not UTF-8 text (byte 0x{raw[exc.start]:02x} at line {line}, byte offset "
                                f"{exc.start}); TOML files must be UTF-8") from None
    name = str(name_or_path)
    shipped = catalogue.names_of(kind)
    if name not in shipped:
        for other, message in elsewhere.items():
            if name in catalogue.names_of(other):
                raise ScenarioError(message.format(name=name))
        raise ScenarioError(f"unknown {kind} {name!r}{catalogue.suggestion(name, catalogue.shipped_names())}; "
                            f"shipped {kind}s: {', '.join(shipped)} (or pass a path to a .toml file)")
    return catalogue.shipped_text(kind, name), name


def with_source(build: Callable[[dict, str], T], data: dict, source: str) -> T:
    """``build(data, source)``, with ``source`` in front of any ScenarioError's message that lacks it."""
    try:
        return build(data, source)
    except ScenarioError as exc:
        if str(exc).startswith(source):
            raise
        raise ScenarioError(f"{source}: {exc}") from None


# --------------------------------------------------------------------------------------------- the fields


class Fields:
    """Reads one TOML table, tracking which keys were consumed so that leftovers are reported."""

    def __init__(self, table: Any, path: str) -> None:
        if not isinstance(table, dict):
            raise ScenarioError(f"{path} must be a table, got {type(table).__name__}")
        self.table, self.path = table, path
        self.used: set[str] = set()

    def _at(self, key: str) -> str:
        return f"{self.path}.{key}" if self.path else key

    def get(self, key: str, default: Any = ..., kind: str = "any") -> Any:
        self.used.add(key)
        if key not in self.table:
            if default is ...:
                raise ScenarioError(f"{self._at(key)} is required")
            return default
        return check(self.table[key], kind, self._at(key))

    def finish(self) -> None:
        extra = sorted(set(self.table) - self.used)
        if extra:
            raise ScenarioError(f"{self._at(extra[0])}: unknown key (allowed here: {', '.join(sorted(self.used))})")


def check(value: Any, kind: str, where: str) -> Any:
    """``value`` as ``kind`` (any, str, name, int, float, vec2, box), or a ScenarioError naming ``where``."""
    if kind == "any":
        return value
    if kind == "str":
        if not isinstance(value, str):
            raise ScenarioError(f"{where} must be a string, got {brief(value)}")
        return value
    if kind == "name":
        if not isinstance(value, str) or not value.isidentifier():
            raise ScenarioError(f"{where} must be a name made of letters, digits and _, got {brief(value)}")
        return value
    if kind == "int":
        if isinstance(value, bool) or not isinstance(value, int):
            raise ScenarioError(f"{where} must be an integer, got {brief(value)}")
        return value
    if kind == "float":
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not is_finite(value):
            raise ScenarioError(f"{where} must be a finite number, got {brief(value)}")
        return float(value)
    if kind == "vec2":
        if not isinstance(value, list) or len(value) != 2:
            raise ScenarioError(f"{where} must be a list of 2 numbers [x, y], got {brief(value)}")
        return tuple(check(v, "float", f"{where}[{i}]") for i, v in enumerate(value))
    if kind == "box":
        if not isinstance(value, list) or len(value) != 4:
            raise ScenarioError(f"{where} must be [xmin, xmax, ymin, ymax], got {brief(value)}")
        box = tuple(check(v, "float", f"{where}[{i}]") for i, v in enumerate(value))
        if not (box[0] < box[1] and box[2] < box[3]):
            raise ScenarioError(f"{where} must have xmin < xmax and ymin < ymax, got {list(box)}")
        return box
    raise AssertionError(kind)  # programming error, not user input


def is_finite(value: int | float) -> bool:
    """``math.isfinite``, False for an integer too large for a float."""
    try:
        return math.isfinite(value)
    except OverflowError:
        return False


def positive(value: float, where: str, allow_zero: bool = False) -> float:
    """``value`` if it is > 0 (>= 0 with ``allow_zero``), else a ScenarioError naming ``where``."""
    if value < 0 or (value == 0 and not allow_zero):
        raise ScenarioError(f"{where} must be {'>= 0' if allow_zero else '> 0'}, got {value}")
    return value


# ------------------------------------------------------------------------------ what every task file holds


@dataclass(frozen=True)
class Header:
    """The top-level fields every task file has (SI units)."""

    name: str
    description: str
    restitution: float
    tf_s: float
    control_period_s: float
    substeps: int


def read_header(top: Fields, default_period_s: float) -> Header:
    """``name``, ``description``, ``restitution``, ``tf_s``, ``control_period_s`` and ``substeps``, checked."""
    name = top.get("name", kind="name")
    description = top.get("description", "", kind="str")
    restitution = top.get("restitution", kind="float")
    if not 0.0 <= restitution <= 1.0:
        raise ScenarioError(f"restitution must be in [0, 1], got {restitution}")
    tf = positive(top.get("tf_s", kind="float"), "tf_s")
    period = positive(top.get("control_period_s", default_period_s, kind="float"), "control_period_s")
    substeps = top.get("substeps", 10, kind="int")
    if substeps < 1:
        raise ScenarioError(f"substeps must be >= 1, got {substeps}")
    return Header(name, description, restitution, tf, period, substeps)


def task_formula(task_source: Any) -> Any:
    """The parsed task of a scenario or station (its ``formula``), an STL error as ``task: ...``."""
    try:
        return task_source.formula
    except STLError as exc:
        raise ScenarioError(f"task: {exc}") from None


def check_horizon(formula: Any, tf_s: float, example: str) -> None:
    """The task must have a temporal operator (``example`` shows one) and end by ``tf_s``."""
    if formula.horizon_s <= 0:
        raise ScenarioError(f"task has no temporal operator, so the episode would have no steps; wrap it, e.g. "
                            f"{example}")
    if formula.horizon_s > tf_s + 1e-9:
        raise ScenarioError(f"task horizon {formula.horizon_s} s exceeds tf_s = {tf_s} s")
