"""The plan file's layout as tables: every field of every JSON object, how it is read and checked.

A plan file (``Plan.save``) is one JSON object with nested objects for bodies, segments and impacts. Each
table below lists one object's fields: name -> :class:`Field` (a reader, and a default when the field is
optional). :func:`read` applies a table to an object, rejects unknown and missing fields, and collects every
problem as ``"bodies.R1.segments[3].control_points: ..."`` so that :class:`~planners.errors.PlanCheckError`
lists them all. A new field is one new row; a new kind of value is one new reader (a function
``(value, where, problems) -> value``, appending to ``problems`` and returning :data:`INVALID` on failure).

An impact-robust plan adds ``delta_mps``, ``funnels`` (per object, :data:`FUNNEL_FIELDS`) and ``copies``
(per impact, :data:`COPIES_FIELDS`); :mod:`planners.plan.funnels` says what they mean.

Limits: times in [0, :data:`MAX_TIME_S`] s, coordinates and velocities within +-:data:`MAX_COORDINATE_M`,
Bezier degree 1.. :data:`MAX_DEGREE` (the planner writes 1 for objects and 2..8 for robots), ``stats`` nested at
most :data:`MAX_STATS_DEPTH` deep, and every number finite (JSON's ``NaN`` and ``Infinity`` are refused).
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Final, Literal

import numpy as np

from impact_env.config_checks import brief
from impact_env.geometry import MAX_COORDINATE_M
from impact_env.limits import MAX_TF_S

MAX_TIME_S = MAX_TF_S
MAX_DEGREE = 8
MAX_STATS_DEPTH = 8
BODY_KINDS = ("robot", "object")

class _Invalid(enum.Enum):
    INVALID = "INVALID"


INVALID: Final = _Invalid.INVALID  # what a reader returns after appending a problem (its own type, so checks narrow)
Reader = Callable[[Any, str, list[str]], Any]


@dataclass(frozen=True)
class Field:
    read: Reader
    default: Any = INVALID  # INVALID: the field is required


def read(data: Any, fields: dict[str, Field], where: str,
         problems: list[str]) -> dict[str, Any] | Literal[_Invalid.INVALID]:
    """Read one JSON object with the table ``fields``; INVALID (and ``problems`` appended) if any field is bad."""
    if not isinstance(data, dict):
        problems.append(f"{where or 'the plan'} must be a JSON object, got {type(data).__name__}")
        return INVALID
    before = len(problems)
    out: dict[str, Any] = {}
    for key in data:
        if key not in fields:
            problems.append(f"{_at(where, key)}: unknown field (allowed: {', '.join(fields)})")
    for key, spec in fields.items():
        if key not in data:
            if spec.default is INVALID:
                problems.append(f"{_at(where, key)} is required")
            else:
                out[key] = spec.default
            continue
        out[key] = spec.read(data[key], _at(where, key), problems)
    return out if len(problems) == before else INVALID


def _at(where: str, key: str) -> str:
    return f"{where}.{key}" if where else key


# ----------------------------------------------------------------------------------------------- readers


def number(value: Any, where: str, problems: list[str], low: float = -math.inf, high: float = math.inf) -> Any:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        problems.append(f"{where} must be a number, got {brief(value)}")
        return INVALID
    try:
        x = float(value)
    except OverflowError:
        x = math.inf
    if not (math.isfinite(x) and low <= x <= high):
        problems.append(f"{where} must be a finite number in [{low:g}, {high:g}], got {brief(value)}")
        return INVALID
    return x


def time_s(value: Any, where: str, problems: list[str]) -> Any:
    return number(value, where, problems, 0.0, MAX_TIME_S)


def non_negative(value: Any, where: str, problems: list[str]) -> Any:
    return number(value, where, problems, 0.0)


def text(value: Any, where: str, problems: list[str]) -> Any:
    if not isinstance(value, str) or len(value) > 1000:
        problems.append(f"{where} must be a string (at most 1000 characters), got {brief(value)}")
        return INVALID
    return value


def name(value: Any, where: str, problems: list[str]) -> Any:
    if not isinstance(value, str) or not value.isidentifier() or len(value) > 100:
        problems.append(f"{where} must be a name made of letters, digits and _, got {brief(value)}")
        return INVALID
    return value


def vec2(value: Any, where: str, problems: list[str]) -> Any:
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        problems.append(f"{where} must be a list of 2 numbers [x, y], got {brief(value)}")
        return INVALID
    xy = [number(v, f"{where}[{i}]", problems, -MAX_COORDINATE_M, MAX_COORDINATE_M) for i, v in enumerate(value)]
    return INVALID if INVALID in xy else (xy[0], xy[1])


def body_kind(value: Any, where: str, problems: list[str]) -> Any:
    if value not in BODY_KINDS or not isinstance(value, str):
        problems.append(f"{where} must be one of {', '.join(map(repr, BODY_KINDS))}, got {brief(value)}")
        return INVALID
    return value


def control_points(value: Any, where: str, problems: list[str]) -> Any:
    """(degree + 1, 2) coordinates, degree 1..MAX_DEGREE."""
    if not isinstance(value, list) or not 2 <= len(value) <= MAX_DEGREE + 1:
        got = f"{len(value)} points" if isinstance(value, list) else brief(value)
        problems.append(f"{where} must be a list of 2 to {MAX_DEGREE + 1} points [x, y] "
                        f"(Bezier degree 1..{MAX_DEGREE}), got {got}")
        return INVALID
    points = [vec2(p, f"{where}[{i}]", problems) for i, p in enumerate(value)]
    return INVALID if INVALID in points else np.array(points, dtype=float)


def time_pair(value: Any, where: str, problems: list[str]) -> Any:
    if not isinstance(value, list) or len(value) != 2:
        problems.append(f"{where} must be [t0_s, t1_s], got {brief(value)}")
        return INVALID
    pair = [time_s(v, f"{where}[{i}]", problems) for i, v in enumerate(value)]
    return INVALID if INVALID in pair else tuple(pair)


def json_data(value: Any, where: str, problems: list[str]) -> Any:
    """Free-form data (``stats``): objects, lists, strings, finite numbers, true/false/null, not too deep."""
    pending = [(value, where, 0)]
    while pending:  # iterative: a tampered file nested a million deep must not exhaust the stack
        item, at, depth = pending.pop()
        if depth > MAX_STATS_DEPTH:
            problems.append(f"{where} is nested more than {MAX_STATS_DEPTH} levels deep (at {at})")
            return INVALID
        if isinstance(item, dict):
            for k, v in item.items():
                if not isinstance(k, str):
                    problems.append(f"{at} has a non-string key {brief(k)}")
                    return INVALID
                pending.append((v, f"{at}.{k}", depth + 1))
        elif isinstance(item, list):
            pending.extend((v, f"{at}[{i}]", depth + 1) for i, v in enumerate(item))
        elif isinstance(item, float) and not math.isfinite(item):
            problems.append(f"{at} must be a finite number, got {item}")
            return INVALID
        elif not (item is None or isinstance(item, (str, int, float, bool))):
            problems.append(f"{at} must be JSON data, got {type(item).__name__}")
            return INVALID
    return value


def _count(low: int, high: int) -> Reader:
    def read_count(value: Any, where: str, problems: list[str]) -> Any:
        if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
            problems.append(f"{where} must be an integer in {low}..{high}, got {brief(value)}")
            return INVALID
        return value
    return read_count


# the entries of ``stats`` that code reads back (the expert's replanner, the plan command's summary): their type
# is checked, the rest is free-form JSON data
STATS_FIELDS: dict[str, Reader] = {
    "intervals": _count(1, 100_000),
    "robot_degree": _count(1, MAX_DEGREE),
    "refine_status": text,
    "refine_s": non_negative,
    "refine_objective": number,
    "polish_s": non_negative,
}


def stats_object(value: Any, where: str, problems: list[str]) -> Any:
    """``stats``: a JSON object of free-form data (:func:`json_data`) whose known entries (:data:`STATS_FIELDS`)
    have their types; a tampered ``"stats": "x"`` is a problem, not an ``AttributeError`` in the expert."""
    if not isinstance(value, dict):
        problems.append(f"{where} must be a JSON object of the planner's numbers, got {brief(value)}")
        return INVALID
    before = len(problems)
    for key, reader in STATS_FIELDS.items():
        if key in value and value[key] is not None:
            reader(value[key], f"{where}.{key}", problems)
    if len(problems) > before:
        return INVALID
    return json_data(value, where, problems)


def table_list(fields: dict[str, Field], non_empty: bool) -> Reader:
    """A reader for a list of objects that each follow ``fields``."""
    def reader(value: Any, where: str, problems: list[str]) -> Any:
        if not isinstance(value, list):
            problems.append(f"{where} must be a list, got {type(value).__name__}")
            return INVALID
        if non_empty and not value:
            problems.append(f"{where} must not be empty")
            return INVALID
        items = [read(v, fields, f"{where}[{i}]", problems) for i, v in enumerate(value)]
        return INVALID if INVALID in items else items
    return reader


def table_map(fields: dict[str, Field]) -> Reader:
    """A reader for a non-empty object {name: object following ``fields``}."""
    def reader(value: Any, where: str, problems: list[str]) -> Any:
        if not isinstance(value, dict) or not value:
            got = "an empty object" if value == {} else type(value).__name__
            problems.append(f"{where} must be a non-empty object {{name: ...}}, got {got}")
            return INVALID
        items = {}
        for key, v in value.items():
            if name(key, f"{where} key", problems) is not INVALID:
                items[key] = read(v, fields, f"{where}.{key}", problems)
        return INVALID if INVALID in items.values() or len(items) != len(value) else items
    return reader


# ------------------------------------------------------------------------------------------------ tables

SEGMENT_FIELDS: dict[str, Field] = {
    "t0_s": Field(time_s),
    "t1_s": Field(time_s),
    "time_control_points": Field(time_pair, None),  # written for readers of the paper's h(s); must be [t0, t1]
    "control_points": Field(control_points),
}

BODY_FIELDS: dict[str, Field] = {
    "kind": Field(body_kind),
    "segments": Field(table_list(SEGMENT_FIELDS, non_empty=True)),
}

IMPACT_FIELDS: dict[str, Field] = {
    "time_s": Field(time_s),
    "time": Field(time_s, None),  # a copy of time_s for readers of the run summaries
    "robot": Field(name),
    "object": Field(name),
    "position": Field(vec2),
    "object_velocity_before": Field(vec2),
    "object_velocity_after": Field(vec2),
    "robot_velocity_before": Field(vec2),
    "robot_velocity_after": Field(vec2),
}

def positive(value: Any, where: str, problems: list[str]) -> Any:
    x = number(value, where, problems, 0.0, MAX_COORDINATE_M)
    if x is not INVALID and x <= 0.0:
        problems.append(f"{where} must be > 0, got {brief(value)}")
        return INVALID
    return x


def optional_non_negative(value: Any, where: str, problems: list[str]) -> Any:
    return None if value is None else number(value, where, problems, 0.0, MAX_COORDINATE_M)


def positive_pair(value: Any, where: str, problems: list[str]) -> Any:
    xy = vec2(value, where, problems)
    if xy is not INVALID and min(xy) <= 0.0:
        problems.append(f"{where} must be two numbers > 0 (half-widths), got {brief(value)}")
        return INVALID
    return xy


def halfwidths(value: Any, where: str, problems: list[str]) -> Any:
    """A non-empty list of [x, y] half-widths >= 0."""
    if not isinstance(value, list) or not value:
        problems.append(f"{where} must be a non-empty list of [x, y] half-widths, got {brief(value)}")
        return INVALID
    rows = [vec2(v, f"{where}[{i}]", problems) for i, v in enumerate(value)]
    if INVALID in rows:
        return INVALID
    if min(min(r) for r in rows) < 0.0:
        problems.append(f"{where}: half-widths must be >= 0")
        return INVALID
    return np.array(rows, dtype=float)


def sign_pairs(value: Any, where: str, problems: list[str]) -> Any:
    """The four (s_p, s_v) pairs of the copies, each -1 or +1."""
    if not isinstance(value, list) or len(value) != 4 or any(
            not isinstance(p, list) or len(p) != 2 or any(type(v) is not int or v not in (-1, 1) for v in p)
            for p in value):
        problems.append(f"{where} must be four pairs [s_p, s_v] of -1 or 1, got {brief(value)}")
        return INVALID
    return [tuple(p) for p in value]


def copy_curves(value: Any, where: str, problems: list[str]) -> Any:
    """Four copies, each a non-empty list of segments' control points of one shape."""
    if not isinstance(value, list) or len(value) != 4:
        problems.append(f"{where} must be a list of 4 copies, got {brief(value)}")
        return INVALID
    out = []
    for j, curve in enumerate(value):
        if not isinstance(curve, list) or not curve:
            problems.append(f"{where}[{j}] must be a non-empty list of segments, got {brief(curve)}")
            return INVALID
        segs = [control_points(c, f"{where}[{j}][{i}]", problems) for i, c in enumerate(curve)]
        if any(s is INVALID for s in segs):
            return INVALID
        if len({s.shape for s in segs}) != 1:
            problems.append(f"{where}[{j}]: every segment must have the same number of control points")
            return INVALID
        out.append(np.array(segs))
    if len({c.shape for c in out}) != 1:
        problems.append(f"{where}: the four copies must have the same shape")
        return INVALID
    return out


FUNNEL_FIELDS: dict[str, Field] = {
    "t0_s": Field(time_s),
    "dt_s": Field(positive),
    "position_halfwidth_m": Field(halfwidths),
    "velocity_halfwidth_mps": Field(halfwidths),
    "final_box_m": Field(positive_pair),
    "final_box_mps": Field(positive_pair),
}

COPIES_FIELDS: dict[str, Field] = {
    "time_s": Field(time_s),
    "robot": Field(name),
    "object": Field(name),
    "window_start_s": Field(time_s),
    "window_end_s": Field(time_s),
    "signs": Field(sign_pairs),
    "before": Field(copy_curves),
    "after": Field(copy_curves),
}

PLAN_FIELDS: dict[str, Field] = {
    "scenario": Field(name),
    "planner": Field(text),
    "robustness": Field(number),
    "solve_time_s": Field(non_negative, 0.0),
    "build_time_s": Field(non_negative, 0.0),
    "mip_gap": Field(non_negative, 0.0),
    "solver": Field(text, ""),
    "stats": Field(stats_object, {}),
    "impacts": Field(table_list(IMPACT_FIELDS, non_empty=False)),
    "bodies": Field(table_map(BODY_FIELDS)),
    # impact-robust plans only (planners.plan.funnels)
    "delta_mps": Field(optional_non_negative, None),
    "funnels": Field(table_map(FUNNEL_FIELDS), {}),
    "copies": Field(table_list(COPIES_FIELDS, non_empty=False), []),
}
