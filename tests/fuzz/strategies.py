"""Hypothesis strategies: mutations of the shipped scenario files and plans, STL text, actions, env options."""

from __future__ import annotations

import copy
import json
import math
import re
import sys
from importlib import resources
from typing import Any

import numpy as np
from hypothesis import strategies as st

from impact_env.transport.scenario import scenario_names
from tests.paths import DATA

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

SCENARIOS = tuple(scenario_names())  # every shipped scenario
TEXTS = {name: resources.files("impact_env.transport.scenarios").joinpath(f"{name}.toml").read_text()
         for name in SCENARIOS}
DICTS = {name: tomllib.loads(text) for name, text in TEXTS.items()}
# copies of the published plans (results/baselines/plans/): key "<scenario>"
PLANS_DIR = DATA / "plans" / "bench"
PLANS = {path.stem: json.loads(path.read_text()) for path in sorted(PLANS_DIR.glob("*.json"))}
# and of the published impact-robust plans (funnels and copies; results/impact_robust/plans/ir/): key
# "<scenario>__ir_plan"
IR_PLANS_DIR = DATA / "plans" / "ir"
PLANS.update({f"{path.stem}__ir_plan": json.loads(path.read_text()) for path in sorted(IR_PLANS_DIR.glob("*.json"))})

# numbers that sit on the edges of what a float, a TOML integer or a physical quantity can be
EXTREME_NUMBERS = [0, 0.0, -0.0, 1, -1, 2, 1e-300, 5e-324, -5e-324, 1e-9, 1e6, 1e7, 1e9, 1e300, 1e308, -1e308,
                   math.inf, -math.inf, math.nan, 2 ** 31, 2 ** 63 - 1, -(2 ** 63), 10 ** 30, 0.5, 0.05, 100.0]
numbers = st.one_of(st.sampled_from(EXTREME_NUMBERS), st.floats(allow_nan=True, allow_infinity=True),
                    st.integers(min_value=-(2 ** 70), max_value=2 ** 70),
                    st.floats(min_value=-20, max_value=20))
scalars = st.one_of(numbers, st.text(max_size=12), st.booleans(), st.none())
values = st.recursive(scalars, lambda inner: st.one_of(st.lists(inner, max_size=5),
                                                       st.dictionaries(st.text(max_size=8), inner, max_size=4)),
                      max_leaves=12)


# ------------------------------------------------------------------------------------------- tree mutation


def _paths(root: Any, max_depth: int = 12) -> list[tuple]:
    """Every path (tuple of keys and indices) into a nested dict/list down to ``max_depth``, the root excluded.
    Iterative and depth-capped: a tree nested 1000 deep by an earlier edit must not exhaust the stack here
    (a RecursionError inside a strategy makes hypothesis's replays inconsistent)."""
    out: list[tuple] = []
    pending = [((), root)]
    while pending:
        prefix, node = pending.pop(0)
        if len(prefix) >= max_depth:
            continue
        items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else []
        for key, child in items:
            out.append(prefix + (key,))
            pending.append((prefix + (key,), child))
    return out


def _parent(root: Any, path: tuple) -> Any:
    node = root
    for key in path[:-1]:
        node = node[key]
    return node


@st.composite
def mutated_tree(draw, base: Any, toml_safe: bool = False, max_edits: int = 4) -> Any:
    """A deep copy of ``base`` with 1..max_edits edits: a number replaced by an extreme one, a value of another
    type, a deleted key or list entry, a duplicated list entry, a new unknown key, deep nesting. With
    ``toml_safe``, no None (TOML has no null) and no NaN-as-None surprises."""
    tree = copy.deepcopy(base)
    for _ in range(draw(st.integers(1, max_edits))):
        paths = _paths(tree)
        if not paths:
            break
        path = draw(st.sampled_from(paths))
        parent, key = _parent(tree, path), path[-1]
        edit = draw(st.sampled_from(["number", "number", "number", "value", "delete", "duplicate", "add", "nest"]))
        current = parent[key]
        if edit == "number" and isinstance(current, (int, float)) and not isinstance(current, bool):
            parent[key] = draw(numbers)
        elif edit == "number" and isinstance(current, list) and current:
            current[draw(st.integers(0, len(current) - 1))] = draw(numbers)
        elif edit == "value":
            parent[key] = draw(values.filter(lambda v: not toml_safe or v is not None))
        elif edit == "delete":
            del parent[key]
        elif edit == "duplicate" and isinstance(current, list) and current:
            # a shallow copy: deepcopy would recurse through a nest an earlier edit made
            current.append(copy.copy(current[draw(st.integers(0, len(current) - 1))]))
        elif edit == "add" and isinstance(current, dict):
            current[draw(st.text(min_size=1, max_size=8))] = draw(values.filter(lambda v: v is not None))
        elif edit == "nest":
            depth = draw(st.sampled_from([2, 50, 300]))  # deeper nests: the text fuzzers and tests build those
            nested = current
            for _ in range(depth):
                nested = [nested]
            parent[key] = nested
    return tree


# ------------------------------------------------------------------------------------------- text mutation


@st.composite
def mutated_bytes(draw, text: str, max_edits: int = 6) -> bytes:
    """The text's UTF-8 bytes with a few byte-level edits (flip, delete a span, insert, duplicate a line)."""
    data = bytearray(text.encode("utf-8"))
    for _ in range(draw(st.integers(1, max_edits))):
        edit = draw(st.sampled_from(["flip", "delete", "insert", "line"]))
        pos = draw(st.integers(0, max(len(data) - 1, 0)))
        if edit == "flip" and data:
            data[pos] = draw(st.integers(0, 255))
        elif edit == "delete":
            del data[pos:pos + draw(st.integers(1, 40))]
        elif edit == "insert":
            data[pos:pos] = draw(st.one_of(st.binary(min_size=1, max_size=8),
                                           st.sampled_from([b"[", b"]", b"{", b"=", b'"', b"\n", b"1e400", b"-",
                                                            b"nan", b"inf", b"\xe9", b"(", b"!"])))
        else:
            lines = bytes(data).split(b"\n")
            k = draw(st.integers(0, len(lines) - 1))
            lines.insert(k, lines[k])
            data = bytearray(b"\n".join(lines))
    return bytes(data)


NAMES = ["O1", "R1", "R2", "goal", "W1", "W2", "obs", "F", "G", "U", "in", "x_9"]


def _formulas():
    name = st.sampled_from(NAMES)
    bound = st.one_of(st.sampled_from(["0", "1", "0.05", "5", "10", "20", "100", "150", "1e2", ".5", "1e400",
                                       "99999999999999999999"]),
                      st.floats(0, 200).map(lambda x: f"{x:g}"))
    interval = st.tuples(bound, bound).map(lambda ab: f"[{ab[0]},{ab[1]}]")
    atom = st.one_of(st.tuples(name, name).map(lambda br: f"in({br[0]}, {br[1]})"), st.sampled_from(["true", "false"]))

    def extend(inner):
        return st.one_of(
            inner.map(lambda f: f"!{f}"), inner.map(lambda f: f"({f})"),
            st.tuples(st.sampled_from(["F", "G"]), interval, inner).map(lambda t: f"{t[0]}{t[1]} {t[2]}"),
            st.tuples(inner, st.sampled_from([" & ", " | "]), inner).map("".join),
            st.tuples(inner, interval, inner).map(lambda t: f"({t[0]} U{t[1]} {t[2]})"),
        )
    return st.recursive(atom, extend, max_leaves=12)


formulas = _formulas()


@st.composite
def stl_texts(draw) -> str:
    """Grammar-generated formulas, sometimes with character edits, plus deep nests and raw junk."""
    kind = draw(st.sampled_from(["grammar", "grammar", "edited", "deep", "junk"]))
    if kind == "junk":
        return draw(st.text(max_size=60))
    if kind == "deep":
        op = draw(st.sampled_from(["!", "(", "F[0,10] ", "G[0,1] "]))
        depth = draw(st.sampled_from([10, 99, 100, 101, 500, 5000]))
        core = "in(O1, goal)"
        return op * depth + core + (")" * depth if op == "(" else "")
    text = draw(formulas)
    if kind == "edited":
        chars = list(text)
        for _ in range(draw(st.integers(1, 4))):
            pos = draw(st.integers(0, max(len(chars) - 1, 0)))
            chars[pos:pos + draw(st.integers(0, 2))] = draw(st.text(max_size=3))
        text = "".join(chars)
    return text


# ------------------------------------------------------------------------------------------------ actions

_dtypes = st.sampled_from(["float32", "float64", "float16", "int64", "int8", "uint8", "bool", "complex64", "U3",
                           "object"])


@st.composite
def numpy_actions(draw) -> np.ndarray:
    shape = draw(st.sampled_from([(6,), (2, 3), (3, 2), (1, 6), (6, 1), (5,), (7,), (), (0,), (2, 3, 1), (3,)]))
    dtype = draw(_dtypes)
    data = draw(st.lists(numbers, min_size=int(np.prod(shape)), max_size=int(np.prod(shape))))
    with np.errstate(all="ignore"):
        try:
            return np.array(data, dtype=object).reshape(shape).astype(dtype)
        except (ValueError, TypeError, OverflowError):
            return np.array(data, dtype=object).reshape(shape)


_finite = st.one_of(st.floats(-1e300, 1e300), st.sampled_from([-1.0, 0.0, 1.0, 0.5, 1e300, -1e300, 5e-324]))
# actions of the right shape: the simulator runs (values beyond [-1, 1] are clipped)
well_formed_actions = st.one_of(
    st.lists(_finite, min_size=6, max_size=6).map(np.array),
    st.lists(_finite, min_size=6, max_size=6).map(lambda v: np.array(v).reshape(2, 3)),
    st.lists(st.floats(-2, 2), min_size=6, max_size=6).map(lambda v: np.array(v, dtype=np.float32)),
    st.lists(st.integers(-5, 5), min_size=6, max_size=6))
well_formed_agent_actions = st.dictionaries(st.sampled_from(["R1", "R2"]),
                                            st.one_of(st.none(), st.lists(_finite, min_size=3, max_size=3)),
                                            max_size=2)
python_actions = st.recursive(st.one_of(numbers, st.text(max_size=4), st.booleans(), st.none()),
                              lambda inner: st.lists(inner, max_size=7), max_leaves=14)


def _mostly(good: st.SearchStrategy, bad: st.SearchStrategy) -> st.SearchStrategy:
    """``good`` in about half of the draws (st.one_of alone drew the well-formed branch far less often)."""
    return st.integers(0, 1).flatmap(lambda k: good if k else bad)


malformed_actions = st.one_of(numpy_actions(), python_actions,
                              st.dictionaries(st.text(max_size=3), python_actions, max_size=3))
actions = _mostly(well_formed_actions, malformed_actions)
agent_actions = _mostly(well_formed_agent_actions, st.one_of(
    st.dictionaries(st.sampled_from(["R1", "R2", "R3", "", "O1"]), st.one_of(numpy_actions(), python_actions),
                    max_size=3),
    malformed_actions, well_formed_actions))


# ----------------------------------------------------------------------------------------------- options

option_numbers = st.one_of(numbers, st.floats(0, 2))
env_options = st.fixed_dictionaries({}, optional={
    "reward_mode": st.sampled_from(["dense", "sparse", "conjuncts", "Dense", "", "shaped"]),
    "fuel_penalty": option_numbers,
    "restitution": st.one_of(st.none(), option_numbers),
    "thrust_noise": option_numbers,
    "initial_position_noise_m": st.one_of(option_numbers, st.sampled_from([0.05, 0.5, 1.5, 3.0, 20.0])),
    "render_width_px": st.one_of(st.integers(-10, 10_000), st.sampled_from([True, 600.0, "600"])),
})


# ----------------------------------------------------------------------- STL: white space and number extremes

# white space the tokenizer must skip in linear time (20,000 trailing spaces once took 87 s), and the kinds it
# must refuse (no-break and em spaces are not STL white space)
WHITESPACE = [" ", "\t", "\n", "\r", "\f", "\v", "\r\n", "  ", "\u00a0", "\u2003", "\u3000", "\ufeff"]
# numbers as the STL text writes them: beyond a float, below the smallest, not finite, long, signed, odd forms
EXTREME_BOUNDS = ["0", "-0", "+5", "1e308", "1.7976931348623157e308", "1e309", "1e-400", "5e-324", "2.5e-324",
                  "1e-9", "inf", "nan", "NaN", "-1", "0x10", "1_000", "1e", "1e+", ".", "00", "007", "1.", ".5e1",
                  "9" * 400, "0." + "0" * 400 + "1", "1" + "0" * 5000, "1e99999999999999999999"]


@st.composite
def stl_extreme_texts(draw) -> str:
    """A grammar formula with runs of white space (up to 20,000 characters) between and around its tokens, and
    with its bounds replaced by extreme numbers."""
    text = draw(formulas)
    if draw(st.booleans()):  # extreme bounds
        bounds = list(re.finditer(r"\[([^,\]]*),([^\]]*)\]", text))
        for m in reversed(bounds[:4]):
            lo = draw(st.one_of(st.sampled_from(EXTREME_BOUNDS), st.just(m.group(1))))
            hi = draw(st.one_of(st.sampled_from(EXTREME_BOUNDS), st.just(m.group(2))))
            text = text[:m.start()] + f"[{lo},{hi}]" + text[m.end():]
    run = st.tuples(st.sampled_from(WHITESPACE), st.sampled_from([1, 2, 10, 1000, 20_000])).map(lambda t: t[0] * t[1])
    tokens = text.split(" ")
    for _ in range(draw(st.integers(0, 3))):  # runs between tokens
        k = draw(st.integers(0, len(tokens)))
        tokens.insert(k, draw(run))
    text = " ".join(tokens)
    if draw(st.booleans()):
        text = draw(run) + text
    if draw(st.booleans()):
        text = text + draw(run)
    return text
