"""The MILP model layer (planners/offline/milp/model.py): its arithmetic and bookkeeping."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planners.offline.milp.model import LinExpr, Model


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
