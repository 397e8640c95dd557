"""STL progression (impact_env.stl.progression) against the robustness definition on random traces."""

from __future__ import annotations

import math

import numpy as np
import pytest

from impact_env.geometry import ConvexPolygon
from impact_env.stl import (
    Always,
    And,
    Constant,
    Eventually,
    InRegion,
    Not,
    Or,
    Until,
    parse,
    progress,
    robustness,
    without_constants,
)
from impact_env.stl.formula import horizon_steps

DT = 0.5
REGIONS = {"A": ConvexPolygon.from_box(0.0, 1.0, 0.0, 1.0), "B": ConvexPolygon.from_box(0.5, 2.0, -1.0, 0.5)}
BODIES = ("P", "Q")


def random_formula(rng: np.random.Generator, depth: int) -> object:
    if depth == 0 or rng.uniform() < 0.2:
        return InRegion(str(rng.choice(BODIES)), str(rng.choice(list(REGIONS))))
    kind = rng.integers(6)
    if kind == 0:
        return Not(random_formula(rng, depth - 1))
    if kind in (1, 2):
        kids = tuple(random_formula(rng, depth - 1) for _ in range(int(rng.integers(2, 4))))
        return And(kids) if kind == 1 else Or(kids)
    a = float(rng.integers(0, 6)) * DT
    b = a + float(rng.integers(0, 8)) * DT
    if kind == 3:
        return Eventually(a, b, random_formula(rng, depth - 1))
    if kind == 4:
        return Always(a, b, random_formula(rng, depth - 1))
    return Until(a, b, random_formula(rng, depth - 1), random_formula(rng, depth - 1))


def random_trace(rng: np.random.Generator, n: int) -> dict[str, np.ndarray]:
    return {b: np.cumsum(rng.normal(0.0, 0.3, (n, 2)), axis=0) + rng.uniform(0, 1, 2) for b in BODIES}


@pytest.mark.parametrize("seed", range(40))
def test_progressed_formula_has_the_robustness_of_the_original_on_every_continuation(seed):
    rng = np.random.default_rng(seed)
    phi = random_formula(rng, depth=3)
    n = horizon_steps(phi, DT) + int(rng.integers(1, 6))
    trace = random_trace(rng, n)
    for k in sorted({0, int(rng.integers(0, n)), n - 1}):
        psi = progress(phi, trace, REGIONS, DT, k)
        # the prefix alone decides psi: every continuation after sample k gives the original's robustness
        for _ in range(3):
            other = {b: np.vstack([trace[b][:k + 1], random_trace(rng, n - k - 1)[b] if n - k - 1 else
                                   np.zeros((0, 2))]) for b in BODIES}
            expected = robustness(phi, other, REGIONS, DT)
            got = robustness(psi, {b: other[b][k:] for b in BODIES}, REGIONS, DT)
            assert got == pytest.approx(expected, abs=1e-12), f"{phi} at k={k}: psi = {psi}"


def test_top_level_task_progresses_into_constants_and_shifted_windows():
    phi = parse("F[0,10] in(P, A) & G[0,10] !in(Q, B)")
    # P sits in A's centre from t = 1 s; Q far from B throughout
    n = 9  # samples 0..8, the cut at t = 4 s
    trace = {"P": np.tile([0.5, 0.5], (n, 1)), "Q": np.tile([5.0, 5.0], (n, 1))}
    trace["P"][0] = [-1.0, 0.5]
    psi = progress(phi, trace, REGIONS, DT)
    past_g = robustness(parse("G[0,3.5] !in(Q, B)"), trace, REGIONS, DT)
    assert psi == And((Or((Eventually(0.0, 6.0, InRegion("P", "A")), Constant(0.5))),
                       Always(0.0, 6.0, Not(InRegion("Q", "B"))), Constant(past_g)))
    # the planner's task for the rest: the satisfied F is gone, the G window starts at the cut
    assert without_constants(psi) == Always(0.0, 6.0, Not(InRegion("Q", "B")))


def test_windows_wholly_in_the_past_become_one_constant_and_future_ones_shift():
    phi = parse("F[0,1] in(P, A) & F[5,6] in(P, B)")
    trace = {"P": np.tile([3.0, 3.0], (5, 1)), "Q": np.zeros((5, 2))}  # cut at t = 2 s: F[0,1] is over, missed
    psi = progress(phi, trace, REGIONS, DT)
    assert psi == And((Eventually(3.0, 4.0, InRegion("P", "B")), Constant(-math.hypot(2.0, 2.0))))
    # the violated, decided conjunct is dropped for planning: only the future window is left
    assert without_constants(psi) == Eventually(3.0, 4.0, InRegion("P", "B"))


def test_progressing_at_sample_zero_changes_nothing_and_bad_cuts_are_errors():
    phi = parse("F[0,2] in(P, A) U[0,1] in(Q, B)")
    trace = random_trace(np.random.default_rng(0), 4)
    assert progress(phi, trace, REGIONS, DT, 0) == phi
    from impact_env.errors import STLError

    with pytest.raises(STLError, match="cut sample k must be in 0..3"):
        progress(phi, trace, REGIONS, DT, 4)


def test_constant_leaf_robustness_and_validation():
    trace = random_trace(np.random.default_rng(1), 3)
    assert robustness(Constant(0.25) & parse("F[0,1] in(P, A)") | Constant(-7.0), trace, REGIONS, DT) == \
        pytest.approx(max(-7.0, min(0.25, robustness(parse("F[0,1] in(P, A)"), trace, REGIONS, DT))))
    from impact_env.errors import STLError

    with pytest.raises(STLError, match="must not be NaN"):
        Constant(float("nan"))
