"""The compiled STL monitor (impact_env.stl.compiled) against OnlineMonitor: the same value to the last bit (the
sign of a zero included) after every sample, the same live state and finality, the same errors, on every shipped
task and each of its conjuncts, and on random formulas of its class over boxes and polygons; formulas outside
the class are left to OnlineMonitor."""

from __future__ import annotations

import math
import pickle

import numpy as np
import pytest

from impact_env.errors import STLBindingError, STLError
from impact_env.geometry import ConvexPolygon
from impact_env.stl import (
    Always,
    And,
    Eventually,
    FalseFormula,
    InRegion,
    Not,
    OnlineMonitor,
    Or,
    TrueFormula,
    Until,
    conjuncts,
    parse,
)
from impact_env.stl.compiled import CompiledMonitor, compiled_monitor
from impact_env.transport.scenario import load_scenario, scenario_names

pytestmark = pytest.mark.skipif(compiled_monitor(parse("in(A, r)"), {"r": ConvexPolygon.from_box(0, 1, 0, 1)}, 0.1)
                                is None, reason="the compiled monitor is not built")

REGIONS = {
    "box": ConvexPolygon.from_box(1.0, 3.0, 1.0, 2.0),
    "wide": ConvexPolygon.from_box(0.0, 6.0, 0.0, 1.0),
    "tri": ConvexPolygon.from_vertices([(2.0, 2.0), (5.0, 2.5), (3.0, 4.5)]),
    "hex": ConvexPolygon.from_vertices([(4.0 + math.cos(a), 1.0 + math.sin(a))
                                        for a in np.linspace(0.0, 2.0 * math.pi, 7)[:-1]]),
}
BODIES = ("A", "B", "C")


def same(a: float, b: float) -> bool:
    """Equal to the last bit, the sign of a zero included (NaN equal to NaN)."""
    return (math.isnan(a) and math.isnan(b)) or (a == b and math.copysign(1.0, a) == math.copysign(1.0, b))


def trace(rng: np.random.Generator, n: int, bodies: int, box=(-1.0, 7.0, -1.0, 5.0)) -> np.ndarray:
    """A random walk of ``bodies`` points, with some samples put exactly on region corners and edges (distance
    0, where the sign of a zero shows)."""
    xmin, xmax, ymin, ymax = box
    p = np.column_stack([rng.uniform(xmin, xmax, bodies), rng.uniform(ymin, ymax, bodies)])
    exact = [(1.0, 1.0), (3.0, 2.0), (1.0, 1.5), (2.0, 2.0), (6.0, 0.5), (0.0, 0.0)]
    out = []
    for _ in range(n):
        p = p + rng.normal(0.0, 0.3, p.shape)
        q = p.copy()
        if rng.random() < 0.2:
            q[rng.integers(bodies)] = exact[rng.integers(len(exact))]
        out.append(q)
    return np.array(out)


def compare(formula, regions, dt, names, samples: np.ndarray) -> None:
    """Both monitors over ``samples`` ((n, bodies, 2)), through update (dict) and update_rows (state array)."""
    reference = OnlineMonitor(formula, regions, dt)
    fast = compiled_monitor(formula, regions, dt, names)
    by_dict = CompiledMonitor(formula, regions, dt)
    assert fast is not None, formula
    for episode in range(2):
        for m in (reference, fast, by_dict):
            m.reset()
        for k, xy in enumerate(samples):
            state = np.zeros((len(names), 6))
            state[:, :2] = xy
            positions = {n: (float(x), float(y)) for n, (x, y) in zip(names, xy)}
            want = reference.update(positions)
            for got in (fast.update_rows(state), by_dict.update(positions)):
                assert same(got, want), (str(formula), episode, k, got, want)
            assert fast.value == reference.value or same(fast.value, reference.value)
            assert fast.steps == reference.steps == by_dict.steps
            assert fast.is_final == reference.is_final, (str(formula), k)
            assert fast.live_state_size() == reference.live_state_size(), (str(formula), k)
    assert fast.horizon_steps == reference.horizon_steps


@pytest.mark.parametrize("name", scenario_names())
def test_every_shipped_task_and_conjunct_is_compiled_and_gives_the_same_values(name):
    sc = load_scenario(name)
    names = [b.name for b in sc.bodies]
    rng = np.random.default_rng(abs(hash(name)) % 2**32)
    samples = trace(rng, round(sc.formula.horizon_s / sc.control_period_s) + 20, len(names), sc.world_box)
    for formula in (sc.formula, *conjuncts(sc.formula)):
        compare(formula, sc.region_map(), sc.control_period_s, names, samples)


def _static(rng: np.random.Generator, depth: int):
    """A random formula of horizon 0: predicates, constants and And/Or/Not of them."""
    roll = rng.random()
    if depth == 0 or roll < 0.35:
        atom = InRegion(BODIES[rng.integers(3)], list(REGIONS)[rng.integers(len(REGIONS))])
        return Not(atom) if rng.random() < 0.4 else atom
    if roll < 0.4:
        return TrueFormula() if rng.random() < 0.5 else FalseFormula()
    if roll < 0.5:
        return Not(_static(rng, depth - 1))
    kids = tuple(_static(rng, depth - 1) for _ in range(int(rng.integers(2, 4))))
    return And(kids) if rng.random() < 0.5 else Or(kids)


def _term(rng: np.random.Generator, dt: float):
    """F or G over a static formula (or, once in a while, a static formula alone)."""
    if rng.random() < 0.15:
        return _static(rng, 2)
    a = int(rng.integers(0, 12))
    b = a + int(rng.integers(0, 15))
    op = Eventually if rng.random() < 0.5 else Always
    return op(a * dt, b * dt, _static(rng, 2))


def random_formula(rng: np.random.Generator, dt: float):
    """A formula of the compiled class: one term, or And/Or of terms, nested once at most."""
    roll = rng.random()
    if roll < 0.2:
        return _term(rng, dt)
    kids = []
    for _ in range(int(rng.integers(2, 5))):
        if rng.random() < 0.2:
            inner = tuple(_term(rng, dt) for _ in range(2))
            kids.append(And(inner) if rng.random() < 0.5 else Or(inner))
        else:
            kids.append(_term(rng, dt))
    return And(tuple(kids)) if roll < 0.7 else Or(tuple(kids))


def test_random_formulas_of_the_class_over_boxes_and_polygons():
    rng = np.random.default_rng(2026)
    dt = 0.5
    for _ in range(150):
        formula = random_formula(rng, dt)
        compare(formula, REGIONS, dt, list(BODIES), trace(rng, 40, 3))


@pytest.mark.parametrize("text", [
    "in(A, box) U[0,2] in(B, tri)",
    "F[0,2] G[0,1] in(A, box)",
    "G[0,3] (in(A, box) | F[0,1] in(B, box))",
    "!F[0,2] in(A, box)",
    "!(F[0,2] in(A, box) & in(B, box))",
])
def test_formulas_outside_the_class_are_left_to_the_python_monitor(text):
    assert compiled_monitor(parse(text), REGIONS, 0.5) is None
    OnlineMonitor(parse(text), REGIONS, 0.5)  # which takes them


def test_a_non_finite_or_missing_position_raises_the_python_monitors_error():
    formula = parse("F[0,2] in(A, box) & G[0,2] !in(B, tri)")
    fast = compiled_monitor(formula, REGIONS, 0.5, ["A", "B"])
    reference = OnlineMonitor(formula, REGIONS, 0.5)
    state = np.zeros((2, 6))
    state[1, 0] = math.inf
    with pytest.raises(STLError) as want:
        reference.update({"A": (0.0, 0.0), "B": (math.inf, 0.0)})
    with pytest.raises(STLError) as got:
        fast.update_rows(state)
    assert str(got.value) == str(want.value)
    assert fast.steps == 0  # nothing was taken
    with pytest.raises(STLBindingError, match="'B'"):
        compiled_monitor(formula, REGIONS, 0.5, ["A"])
    with pytest.raises(STLBindingError) as got:
        CompiledMonitor(formula, REGIONS, 0.5).update({"A": (0.0, 0.0)})
    with pytest.raises(STLBindingError) as want:
        OnlineMonitor(formula, REGIONS, 0.5).update({"A": (0.0, 0.0)})
    assert str(got.value) == str(want.value)


def test_invalid_arguments_raise_as_for_the_python_monitor():
    for args in ((parse("F[0,1] in(A, nowhere)"), REGIONS, 0.5), (parse("F[0,1] in(A, box)"), REGIONS, -1.0),
                 ("F[0,1] in(A, box)", REGIONS, 0.5)):
        with pytest.raises(STLError) as want:
            OnlineMonitor(*args)
        with pytest.raises(STLError) as got:
            compiled_monitor(*args)
        assert type(got.value) is type(want.value) and str(got.value) == str(want.value)


def test_the_value_is_final_and_frozen_after_the_horizon():
    formula = parse("F[0,2] in(A, box) & G[1,3] !in(A, tri)")
    fast = compiled_monitor(formula, REGIONS, 1.0)
    values = [fast.update({"A": (x, 1.5)}) for x in (5.0, 2.0, 6.0, 6.0, 2.0, 2.5)]
    assert fast.is_final and fast.steps == 6
    assert values[3:] == [values[3]] * 3


def test_a_fresh_compiled_monitor_pickles_and_a_running_one_says_why_not():
    formula = parse("F[0,2] in(A, box)")
    fast = compiled_monitor(formula, REGIONS, 0.5)
    clone = pickle.loads(pickle.dumps(fast))
    assert clone.update({"A": (2.0, 1.5)}) == fast.update({"A": (2.0, 1.5)})
    with pytest.raises(TypeError, match="before its first update"):
        pickle.dumps(fast)


def test_until_is_refused_but_its_parts_are_compiled():
    f = Until(0.0, 1.0, InRegion("A", "box"), InRegion("B", "box"))
    assert compiled_monitor(f, REGIONS, 0.5) is None
    assert compiled_monitor(f.left, REGIONS, 0.5) is not None
