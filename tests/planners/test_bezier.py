"""Bezier utilities against direct formulas; the MILP model layer's arithmetic and bookkeeping."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planners import bezier
from planners.offline.milp.model import LinExpr, Model


def _direct(cp: np.ndarray, s: float) -> np.ndarray:
    d = len(cp) - 1
    return sum(math.comb(d, b) * (1 - s) ** (d - b) * s ** b * cp[b] for b in range(d + 1))


@pytest.fixture
def cp():
    return np.random.default_rng(0).uniform(-2, 2, (5, 2))


def test_evaluate_matches_the_bernstein_sum(cp):
    s = np.linspace(0, 1, 11)
    np.testing.assert_allclose(bezier.evaluate(cp, s), [_direct(cp, x) for x in s], atol=1e-12)
    np.testing.assert_allclose(bezier.evaluate(cp, 0.0)[0], cp[0])
    np.testing.assert_allclose(bezier.evaluate(cp, 1.0)[0], cp[-1])


def test_derivative_matches_finite_differences(cp):
    s = np.linspace(0.05, 0.95, 7)
    h = 1e-6
    fd = (bezier.evaluate(cp, s + h) - bezier.evaluate(cp, s - h)) / (2 * h)
    np.testing.assert_allclose(bezier.evaluate(bezier.derivative(cp), s), fd, atol=1e-6)


def test_split_and_elevate_are_the_same_curve(cp):
    left, right = bezier.split(cp, 0.3)
    s = np.linspace(0, 1, 9)
    np.testing.assert_allclose(bezier.evaluate(left, s), bezier.evaluate(cp, 0.3 * s), atol=1e-12)
    np.testing.assert_allclose(bezier.evaluate(right, s), bezier.evaluate(cp, 0.3 + 0.7 * s), atol=1e-12)
    np.testing.assert_allclose(bezier.evaluate(bezier.elevate(cp), s), bezier.evaluate(cp, s), atol=1e-12)


def test_bounding_box_contains_the_curve(cp):
    lo, hi = bezier.bounding_box(cp)
    pts = bezier.evaluate(cp, np.linspace(0, 1, 200))
    assert np.all(pts >= lo - 1e-12) and np.all(pts <= hi + 1e-12)


def test_linexpr_arithmetic_and_constraints():
    m = Model()
    x, y = m.add_var(0, 10, name="x"), m.add_var(name="y")
    e = 2 * x - (y - 3) / 2 + 1
    assert e.terms == {0: 2.0, 1: -0.5} and e.const == 2.5
    m.add(e <= 4, group="g1")
    m.add([x >= 1, y == 2], group="g2")
    assert m.groups() == ["g1", "g2"] and m.n_rows == 3
    assert m.rows[0] == ({0: 2.0, 1: -0.5}, -math.inf, 1.5)  # constant moved to the bound
    assert m.check(np.array([1.0, 2.0])) == []
    assert any("g1" in v for v in m.check(np.array([5.0, 2.0])))
    assert m.without_groups({"g1"}).n_rows == 2
    with pytest.raises(TypeError):
        x * y
    with pytest.raises(ValueError, match="can never hold"):
        m.add(LinExpr.of(1.0) <= 0.0, group="bad")


def test_quadratic_terms_need_minimisation():
    m = Model()
    x = m.add_var()
    with pytest.raises(ValueError, match="minimised"):
        m.add_quadratic(x)
    m.set_objective(LinExpr(), maximize=False)
    m.add_quadratic(x - 1.0, 2.0)  # 2 (x - 1)^2 = 2 x^2 - 4 x + 2
    assert m.quadratic == {(0, 0): 2.0} and m.objective.terms == {0: -4.0}
