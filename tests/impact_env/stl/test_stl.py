"""STL: parser, offline robustness (vs hand-computed values and a brute-force reference), online monitor."""

from __future__ import annotations

import math
import random

import numpy as np
import pytest

from impact_env.errors import STLBindingError, STLError, STLSyntaxError
from impact_env.geometry import ConvexPolygon
from impact_env.stl import (
    Always,
    And,
    Eventually,
    FalseFormula,
    Formula,
    InRegion,
    Not,
    OnlineMonitor,
    Or,
    TrueFormula,
    Until,
    conjuncts,
    horizon_steps,
    parse,
    robustness,
    robustness_signal,
)

# ------------------------------------------------------------------------------------------------ hand-computed
# Body A moves along y = 0 with dt = 1 s through x = -1, 0.5, 2, 0.25, 3.
# "box" = [0,1] x [-1,1]: signed distance p = -1, 0.5, -1, 0.25, -2 (inside: distance to the nearest edge).
# "left" = [-2,0.75] x [-1,1]: l = 1, 0.25, -1.25, 0.5, -2.25.
XS = [-1.0, 0.5, 2.0, 0.25, 3.0]
LINE = {"A": np.array([[x, 0.0] for x in XS])}
BOXES = {"box": ConvexPolygon.from_box(0.0, 1.0, -1.0, 1.0), "left": ConvexPolygon.from_box(-2.0, 0.75, -1.0, 1.0)}


@pytest.mark.parametrize("text, expected", [
    ("in(A, box)", -1.0),
    ("!in(A, box)", 1.0),
    ("F[0,4] in(A, box)", 0.5),  # max(p)
    ("G[0,4] in(A, box)", -2.0),  # min(p)
    ("F[2,3] in(A, box)", 0.25),  # max(p2, p3)
    ("G[0,4] F[0,1] in(A, box)", -2.0),  # F[0,1] signal 0.5, 0.5, 0.25, 0.25, -2 (last held); min
    ("G[0,3] F[0,1] in(A, box)", 0.25),
    ("F[0,10] in(A, box)", 0.5),  # beyond the trace the last sample (-2) is held
    ("F[10,20] in(A, box)", -2.0),  # only the held last sample
    ("G[3,10] in(A, box)", -2.0),
    ("F[0,4] in(A, box) & G[0,1] in(A, left)", 0.25),  # min(0.5, min(1, 0.25))
    ("in(A, box) | in(A, left)", 1.0),
    # tau=0: min(-1, 1); tau=1: min(0.5, min(1, 0.25)) = 0.25; tau=2: min(-1, .) -> 0.25
    ("in(A, left) U[0,2] in(A, box)", 0.25),
    # tau=3: min(0.25, min(l0..l3) = -1.25) = -1.25 does not beat tau=1
    ("in(A, left) U[1,3] in(A, box)", 0.25),
    # closed interval [t, tau]: at tau=1 left = -p1 = -0.5 counts, min(0.5, min(1, -0.5)) = -0.5
    ("!in(A, box) U[1,1] in(A, box)", -0.5),
    ("true", math.inf),
    ("false | in(A, box)", -1.0),
])
def test_hand_computed_robustness(text: str, expected: float) -> None:
    assert robustness(parse(text), LINE, BOXES, dt=1.0) == pytest.approx(expected, abs=1e-12)


def test_hand_computed_signals() -> None:
    sig = robustness_signal(parse("F[0,1] in(A, box)"), LINE, BOXES, dt=1.0)
    np.testing.assert_allclose(sig, [0.5, 0.5, 0.25, 0.25, -2.0], atol=1e-12)
    # t=2: tau=2 min(-1, -1.25); tau=3 min(0.25, min(-1.25, 0.5)); tau=4 min(-2, .) -> -1.25
    sig = robustness_signal(parse("in(A, left) U[0,2] in(A, box)"), LINE, BOXES, dt=1.0)
    assert sig[2] == pytest.approx(-1.25, abs=1e-12)
    # dt = 0.5: [1, 1.5] s covers samples 2..3
    assert robustness(parse("F[1,1.5] in(A, box)"), LINE, BOXES, dt=0.5) == pytest.approx(0.25)
    # [0.6, 1.4] s at dt = 0.5 covers only sample 2 (ceil(1.2) .. floor(2.8))
    assert robustness(parse("F[0.6,1.4] in(A, box)"), LINE, BOXES, dt=0.5) == pytest.approx(-1.0)


# -------------------------------------------------------------------------------------- random formulas, traces
BODIES = ("A", "B")


def random_regions(rng: random.Random) -> dict[str, ConvexPolygon]:
    regions = {"r0": ConvexPolygon.from_box(-1.0, 0.5, -0.5, 1.0)}
    for i in (1, 2):
        n, radius = rng.randint(3, 6), rng.uniform(0.5, 1.5)
        cx, cy, phase = rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(0, 2 * math.pi)
        angles = [phase + 2 * math.pi * j / n for j in range(n)]
        regions[f"r{i}"] = ConvexPolygon.from_vertices([[cx + radius * math.cos(a), cy + radius * math.sin(a)]
                                                         for a in angles])
    return regions


def random_interval(rng: random.Random, dt: float) -> tuple[float, float]:
    a_k = rng.randint(0, 3)
    b_k = a_k + rng.randint(0, 4)
    a_s, b_s = a_k * dt, b_k * dt
    if rng.random() < 0.3:  # off-grid bounds that still cover a_k .. b_k
        a_s = max(0.0, a_s - 0.6 * dt) if a_k > 0 else 0.0
        b_s = b_s + 0.6 * dt
    return a_s, b_s


def random_formula(rng: random.Random, dt: float, depth: int) -> Formula:
    if depth == 0 or rng.random() < 0.2:
        if rng.random() < 0.05:
            return rng.choice([TrueFormula(), FalseFormula()])
        return InRegion(rng.choice(BODIES), rng.choice(["r0", "r1", "r2"]))
    kind = rng.choice(["not", "and", "or", "F", "G", "U", "F", "G", "U"])
    sub = lambda: random_formula(rng, dt, depth - 1)  # noqa: E731
    if kind == "not":
        return Not(sub())
    if kind in ("and", "or"):
        kids = tuple(sub() for _ in range(rng.randint(2, 3)))
        return And(kids) if kind == "and" else Or(kids)
    a_s, b_s = random_interval(rng, dt)
    if kind == "U":
        return Until(a_s, b_s, sub(), sub())
    return (Eventually if kind == "F" else Always)(a_s, b_s, sub())


def random_trace(nrng: np.random.Generator, n: int) -> dict[str, np.ndarray]:
    return {b: np.cumsum(nrng.normal(0.0, 0.4, (n, 2)), axis=0) + nrng.uniform(-1, 1, 2) for b in BODIES}


def brute_force_signal(f: Formula, trace: dict[str, np.ndarray], regions: dict[str, ConvexPolygon],
                       dt: float) -> list[float]:
    """Straight from the definition: explicit hold-last extension, plain loops, memoised recursion."""
    n = len(trace["A"])
    ext_len = n + horizon_steps(f, dt) + 1
    ext = {b: [tuple(p[min(i, n - 1)]) for i in range(ext_len)] for b, p in trace.items()}
    memo: dict[tuple[int, int], float] = {}

    def steps(a_s: float, b_s: float) -> range:
        return range(math.ceil(a_s / dt - 1e-9), math.floor(b_s / dt + 1e-9) + 1)

    def rho(g: Formula, t: int) -> float:
        key = (id(g), t)
        if key not in memo:
            memo[key] = value(g, t)
        return memo[key]

    def value(g: Formula, t: int) -> float:
        if isinstance(g, InRegion):
            x, y = ext[g.body][t]
            return regions[g.region].signed_distance_xy(x, y)
        if isinstance(g, TrueFormula):
            return math.inf
        if isinstance(g, FalseFormula):
            return -math.inf
        if isinstance(g, Not):
            return -rho(g.child, t)
        if isinstance(g, And):
            return min(rho(c, t) for c in g.children)
        if isinstance(g, Or):
            return max(rho(c, t) for c in g.children)
        if isinstance(g, Eventually):
            return max(rho(g.child, t + j) for j in steps(g.a_s, g.b_s))
        if isinstance(g, Always):
            return min(rho(g.child, t + j) for j in steps(g.a_s, g.b_s))
        assert isinstance(g, Until)
        return max(min(rho(g.right, t + j), min(rho(g.left, t + i) for i in range(j + 1)))
                   for j in steps(g.a_s, g.b_s))

    return [rho(f, t) for t in range(n)]


@pytest.mark.parametrize("seed", range(6))
def test_robustness_signal_matches_brute_force(seed: int) -> None:
    rng, nrng = random.Random(seed), np.random.default_rng(seed)
    for _ in range(50):
        dt = rng.choice([0.1, 0.5, 1.0])
        regions = random_regions(rng)
        f = random_formula(rng, dt, depth=rng.randint(1, 3))
        trace = random_trace(nrng, rng.randint(1, 25))
        got = robustness_signal(f, trace, regions, dt)
        want = brute_force_signal(f, trace, regions, dt)
        np.testing.assert_allclose(got, want, atol=1e-9, rtol=0, err_msg=str(f))


def test_conjuncts_split_the_formula_exactly() -> None:
    f = parse("F[0,3] in(A, r1) & G[0,2] (!in(A, r0) & (!in(B, r0) & !in(B, r2))) & (in(A, r2) | in(B, r1))")
    parts = conjuncts(f)
    assert [str(p) for p in parts] == [str(parse(t)) for t in (
        "F[0,3] in(A, r1)", "G[0,2] !in(A, r0)", "G[0,2] !in(B, r0)", "G[0,2] !in(B, r2)", "in(A, r2) | in(B, r1)")]
    assert conjuncts(parse("F[0,1] in(A, r1)")) == (parse("F[0,1] in(A, r1)"),)
    rng, nrng = random.Random(7), np.random.default_rng(7)
    for _ in range(30):  # rho(f) = min over the parts, on random traces and regions
        regions, trace = random_regions(rng), random_trace(nrng, rng.randint(1, 12))
        want = robustness(f, trace, regions, 0.5)
        assert min(robustness(p, trace, regions, 0.5) for p in parts) == pytest.approx(want, abs=1e-12)


# --------------------------------------------------------------------------------------------------- monitor
def assert_monitor_matches_offline(f: Formula, trace: dict[str, np.ndarray], regions: dict, dt: float) -> None:
    monitor = OnlineMonitor(f, regions, dt)
    assert math.isnan(monitor.value) and monitor.steps == 0
    n = len(trace["A"])
    for k in range(n):
        got = monitor.update({b: tuple(p[k]) for b, p in trace.items()})
        want = robustness(f, {b: p[:k + 1] for b, p in trace.items()}, regions, dt)
        assert got == pytest.approx(want, abs=1e-9), f"{f} at k={k}"
        assert monitor.value == got and monitor.steps == k + 1
        assert monitor.is_final == (k >= monitor.horizon_steps)
        if monitor.is_final:  # everything was consumed: no accumulator or buffered value is left behind
            assert monitor.live_state_size() == 0


@pytest.mark.parametrize("text, dt", [
    ("G[0,3] F[1,2] in(A, r1)", 0.5),
    ("in(A, r1) U[1,3] F[0,2] in(B, r2)", 0.5),
    ("F[0,2] (in(A, r1) U[0,3] in(B, r2))", 0.5),
    ("G[0,2] (in(A, r0) & F[0,1.5] in(B, r1)) | !F[1,2] G[0,1] in(A, r2)", 0.5),
    ("F[0,3] in(A, r0) U[0.5,2] G[0,1] in(B, r2)", 0.5),
    ("G[1,4] (in(A, r1) | F[2,3] in(A, r2))", 1.0),
])
def test_monitor_matches_offline_nested(text: str, dt: float) -> None:
    nrng = np.random.default_rng(1)
    regions = random_regions(random.Random(1))
    f = parse(text)
    assert_monitor_matches_offline(f, random_trace(nrng, horizon_steps(f, dt) + 6), regions, dt)


@pytest.mark.parametrize("seed", range(4))
def test_monitor_matches_offline_random(seed: int) -> None:
    rng, nrng = random.Random(100 + seed), np.random.default_rng(seed)
    for _ in range(40):
        dt = rng.choice([0.1, 0.5, 1.0])
        regions = random_regions(rng)
        f = random_formula(rng, dt, depth=rng.randint(1, 3))
        n = min(horizon_steps(f, dt) + rng.randint(1, 6), 45)
        assert_monitor_matches_offline(f, random_trace(nrng, n), regions, dt)


def test_monitor_reset_and_errors() -> None:
    regions = random_regions(random.Random(2))
    trace = random_trace(np.random.default_rng(2), 12)
    monitor = OnlineMonitor(parse("F[0,3] in(A, r1) & G[1,5] !in(B, r2)"), regions, dt=0.5)
    first = [monitor.update({b: p[k] for b, p in trace.items()}) for k in range(12)]
    monitor.reset()
    assert monitor.steps == 0 and math.isnan(monitor.value)
    assert [monitor.update({b: p[k] for b, p in trace.items()}) for k in range(12)] == first
    with pytest.raises(STLBindingError, match="formula names body 'B' but the positions have A"):
        monitor.update({"A": (0.0, 0.0)})
    with pytest.raises(STLError, match="finite"):
        monitor.update({"A": (0.0, 0.0), "B": (math.nan, 0.0)})
    with pytest.raises(STLBindingError, match="region 'r9'"):
        OnlineMonitor(parse("F[0,1] in(A, r9)"), regions, dt=0.5)
    with pytest.raises(STLError, match=r"interval \[0.2, 0.3\] s contains no sample at dt = 0.5"):
        OnlineMonitor(parse("F[0.2,0.3] in(A, r1)"), regions, dt=0.5)


class CountingBox(ConvexPolygon):
    """A box that counts its scalar signed-distance calls (the monitor's predicate evaluations)."""

    calls = 0

    def signed_distance_xy(self, x: float, y: float) -> float:
        CountingBox.calls += 1
        return super().signed_distance_xy(x, y)


def run_monitor(text: str, n: int) -> tuple[list[int], list[int]]:
    """Live state size and number of predicate evaluations after each of n updates at dt = 0.1 s."""
    regions = {"goal": CountingBox(ConvexPolygon.from_box(4, 5, 0, 1).vertices),
               "bad": CountingBox(ConvexPolygon.from_box(1, 2, 0, 1).vertices)}
    monitor = OnlineMonitor(parse(text), regions, dt=0.1)
    assert monitor.horizon_steps > n  # the monitor must keep working during the whole trace
    sizes, calls = [], []
    for k in range(n):
        before = CountingBox.calls
        monitor.update({"A": (0.001 * k, 0.5), "B": (math.sin(0.01 * k), 0.3)})
        sizes.append(monitor.live_state_size())
        calls.append(CountingBox.calls - before)
    return sizes, calls


def test_monitor_work_is_bounded_for_flat_formula() -> None:
    # per-step work is the predicate evaluations plus a pass over the live state (accumulators, buffers,
    # tentative values); neither may grow with k
    sizes, calls = run_monitor("F[0,1000] in(A, goal) & G[0,1000] (!in(A, bad) & !in(B, bad))", 5000)
    assert max(sizes) <= 5
    assert sizes[10] == sizes[4999]
    assert set(calls) == {3}


def test_monitor_work_is_bounded_by_nested_window() -> None:
    # F[0,2] at dt = 0.1 spans 21 samples: at most 21 accumulators and 20 tentative values, whatever k is
    sizes, calls = run_monitor("G[0,1000] F[0,2] in(A, goal)", 5000)
    assert max(sizes) <= 2 * 21 + 4
    assert max(sizes[4000:]) == max(sizes[100:1100])
    assert set(calls) == {1}


# ---------------------------------------------------------------------------------------------------- parser
P, Q, S = InRegion("O1", "goal"), InRegion("R1", "W1"), InRegion("R2", "W2")


@pytest.mark.parametrize("text, tree", [
    ("F[0,100] in(O1, goal) & G[0,100] !in(R1, W1)", And((Eventually(0, 100, P), Always(0, 100, Not(Q))))),
    ("in(O1,goal)|in(R1,W1)&in(R2,W2)", Or((P, And((Q, S))))),
    ("in(O1, goal) & in(R1, W1) & in(R2, W2)", And((P, Q, S))),
    ("(in(O1, goal) & in(R1, W1)) & in(R2, W2)", And((And((P, Q)), S))),
    ("in(O1, goal) U[0,1] in(R1, W1) & in(R2, W2)", And((Until(0, 1, P, Q), S))),
    ("!in(O1, goal) U[0, 1e2] F[.5, 2.5] in(R1, W1)", Until(0, 100, Not(P), Eventually(0.5, 2.5, Q))),
    ("G[0,5]F[1,2]!in(O1,goal)", Always(0, 5, Eventually(1, 2, Not(P)))),
    ("in(F, U) | true & !false", Or((InRegion("F", "U"), And((TrueFormula(), Not(FalseFormula())))))),
])
def test_parse_precedence(text: str, tree: Formula) -> None:
    assert parse(text) == tree
    assert parse(str(tree)) == tree


def test_round_trip_random_formulas() -> None:
    rng = random.Random(7)
    for _ in range(300):
        f = random_formula(rng, rng.choice([0.1, 0.5, 1.0]), depth=3)
        assert parse(str(f)) == f, str(f)
    nested = Until(1e-5, 2.5e20, Until(0, 1, P, Q), Or((Or((P, Q)), S)))
    assert parse(str(nested)) == nested


@pytest.mark.parametrize("text, message, column", [
    ("F[0,100 in(O1, goal)", "expected ']' after interval", 8),
    ("F[5,2] in(O1, goal)", "interval [5, 2] has a > b", 1),
    ("in(O1, goal) % in(R1, W1)", "unknown token '%'", 13),
    ("", "unexpected end of formula, expected a predicate like in(O1, goal)", 0),
    ("in(O1, goal) & ", "unexpected end of formula, expected a predicate like in(O1, goal)", 15),
    ("F in(O1, goal)", "expected '[' after 'F'", 2),
    ("F[a,2] in(O1, goal)", "expected a number of seconds", 2),
    ("F[-1,2] in(O1, goal)", "unknown token '-'", 2),
    ("in(O1 goal)", "expected ','", 6),
    ("in(O1, goal", "expected ')' to close in(O1, goal", 11),
    ("(in(O1, goal) & in(R1, W1)", "expected ')' to close the '(' at column 0", 26),
    ("in(O1, goal))", "unmatched ')'", 12),
    ("in(O1, goal) in(R1, W1)", "unexpected 'in' after a complete formula", 13),
    ("in(O1, goal) U[0,1] in(R1, W1) U[0,1] in(R2, W2)", "'U' is not associative", 31),
    ("inside(O1, goal)", "unknown name 'inside'", 0),
    ("& in(O1, goal)", "expected a predicate like in(O1, goal) before '&'", 0),
])
def test_parse_errors(text: str, message: str, column: int) -> None:
    with pytest.raises(STLSyntaxError) as info:
        parse(text)
    assert message in str(info.value)
    assert info.value.column == column


def test_formula_construction_and_horizons() -> None:
    f = parse("F[0,10] in(O1, goal) & G[2,5] (in(R1, W1) U[1,3] F[0,2] in(R2, W2))")
    assert f.horizon_s == 10.0  # max(10, 5 + 3 + 2)
    assert horizon_steps(f, 0.5) == 20 and horizon_steps(f, 0.3) == 33  # G: 16 + U: 10 + F: 6 = 32 < 33
    assert f.bodies() == {"O1", "R1", "R2"} and f.regions() == {"goal", "W1", "W2"}
    assert (P & Q & S) == And((P, Q, S)) and (P | Q | S) == Or((P, Q, S)) and ~P == Not(P)
    assert P.until(Q, 0, 1) == Until(0, 1, P, Q)
    for bad in (lambda: Eventually(2, 1, P), lambda: Always(-1, 1, P), lambda: Until(0, math.inf, P, Q),
                lambda: InRegion("1st", "goal"), lambda: And((P,)), lambda: Not("in(O1, goal)")):
        with pytest.raises(STLError):
            bad()


# ------------------------------------------------------------------------------------------- input validation
def test_binding_and_input_errors() -> None:
    regions = {"goal": ConvexPolygon.from_box(0, 1, 0, 1)}
    trace = {"R1": np.zeros((3, 2)), "R2": np.zeros((3, 2)), "O1": np.zeros((3, 2))}
    with pytest.raises(STLBindingError) as info:
        robustness(parse("F[0,1] in(R3, goal)"), trace, regions, dt=0.1)
    assert str(info.value) == "formula names body 'R3' but the trace has R1, R2, O1"
    with pytest.raises(STLBindingError, match="formula names region 'W1' but the regions are goal"):
        robustness(parse("in(R1, W1)"), trace, regions, dt=0.1)
    f = parse("F[0,1] in(R1, goal) & in(O1, goal)")
    for bad_trace, message in [
        ({"R1": np.zeros((0, 2)), "O1": np.zeros((0, 2))}, "empty"),
        ({"R1": np.zeros((3, 2)), "O1": np.zeros((4, 2))}, "lengths differ"),
        ({"R1": np.full((3, 2), np.nan), "O1": np.zeros((3, 2))}, "NaN"),
        ({"R1": np.zeros((3, 3)), "O1": np.zeros((3, 2))}, "shape"),
    ]:
        with pytest.raises(STLError, match=message):
            robustness(f, bad_trace, regions, dt=0.1)
    for dt in (0.0, -1.0, math.nan):
        with pytest.raises(STLError, match="dt must be"):
            robustness(f, trace, regions, dt=dt)
    with pytest.raises(STLError, match="contains no sample"):
        robustness(parse("G[0.02,0.08] in(R1, goal)"), trace, regions, dt=0.1)


# ---------------------------------------------------------------------------------------------- geometry check
def test_signed_distance_matches_shapely() -> None:
    shapely = pytest.importorskip("shapely")
    rng = random.Random(3)
    nrng = np.random.default_rng(3)
    for _ in range(20):
        polygon = random_regions(rng)[rng.choice(["r0", "r1", "r2"])]
        shape = shapely.Polygon(polygon.vertices)
        points = nrng.uniform(-3, 3, (50, 2))
        got = polygon.signed_distance(points)
        for (x, y), d in zip(points, got, strict=True):
            point = shapely.Point(x, y)
            want = shape.exterior.distance(point) * (1.0 if shape.contains(point) else -1.0)
            assert d == pytest.approx(want, abs=1e-9)
            assert polygon.signed_distance_xy(x, y) == pytest.approx(want, abs=1e-9)
