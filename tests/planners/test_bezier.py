"""Bezier utilities (planners/bezier.py) against direct formulas."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planners import bezier


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
