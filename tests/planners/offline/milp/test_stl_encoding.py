"""Same formula, same encoding: whatever the process encoded before (planners/offline/milp/stl_encoding.py).

The STL encoder memoised encodings by ``id()`` of formula nodes that it did not keep alive. The negation normal
form builds new nodes for every conjunct (e.g. ``!in(R1, pillar)``); once a conjunct was encoded its nodes
were freed, and a node of a later conjunct could be allocated at the same address and be given the earlier
conjunct's encoding. Whether that happened depended on the heap, i.e. on what the process had done before, so
a mission re-plan (and hence an episode) of two_objects could differ between a fresh process and a benchmark
worker that had flown other seeds (tests/planners/expert/test_determinism.py flies those episodes).
"""

from __future__ import annotations

import re

import pytest

from impact_env.geometry import ConvexPolygon
from impact_env.stl import Always, InRegion
from impact_env.transport.scenario import load_scenario
from planners.offline.milp.model import Model
from planners.offline.milp.stl_encoding import STLEncoder
from planners.offline.milp.trajectories import Grid
from planners.offline.solvers import lp_optimum, solve
from planners.offline.spatially_robust import PlannerConfig, build_model

SQUARE = ConvexPolygon.from_vertices([(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)])
INSIDE, OUTSIDE = (0.5, 0.3), (1.5, 0.5)  # body A 0.3 m inside the square, body B 0.5 m outside


def _encoder() -> tuple[Model, STLEncoder]:
    model = Model()
    points = {name: (model.add_var(x, x), model.add_var(y, y)) for name, (x, y) in (("A", INSIDE), ("B", OUTSIDE))}
    box = (-2.0, 3.0, -2.0, 3.0)
    return model, STLEncoder(model, Grid(1, 1.0), lambda body, k: [points[body]], {"A": box, "B": box},
                             {"sq": SQUARE}, lp_optimum=lp_optimum)


def _same_address_as(dead_id: int, make):
    """A new object from ``make()``, at the address ``dead_id`` if CPython's allocator hands it out again
    within a few thousand allocations (it normally does at once), else the last one made."""
    keep = []
    for _ in range(5000):
        obj = make()
        if id(obj) == dead_id:
            return obj
        keep.append(obj)  # held, so that the allocator moves on to other addresses
    return obj


def test_a_formula_freed_after_encoding_does_not_lend_its_encoding_to_a_new_one():
    model, encoder = _encoder()
    first = Always(0.0, 1.0, InRegion("A", "sq"))
    r_a = encoder.encode(first)
    dead = id(first.child)
    del first  # the caller drops its formula, as the planner drops each conjunct's negation normal form
    r_b = encoder.encode(Always(0.0, 1.0, _same_address_as(dead, lambda: InRegion("B", "sq"))))
    model.set_objective(r_a + r_b, maximize=True)
    x = solve(model, "highs").x
    assert r_a.value(x) == pytest.approx(0.3, abs=1e-7)
    assert r_b.value(x) == pytest.approx(-0.5, abs=1e-7)  # B's own distance, not A's +0.3


def test_the_upper_bound_of_a_freed_robustness_variable_is_not_inherited():
    model, encoder = _encoder()
    r = encoder.encode(Always(0.0, 1.0, InRegion("A", "sq")))
    assert encoder.upper_bound(r) < encoder.bound  # A's predicate can reach at most the square's inradius
    dead = id(r)
    del r
    other = _same_address_as(dead, lambda: model.add_var(-1.0, 1.0))
    assert encoder.upper_bound(other) == encoder.bound  # a stranger to the encoder: only the scene's bound


def test_each_pillar_conjunct_of_two_objects_has_its_own_robustness_variables():
    built = build_model(load_scenario("two_objects"), PlannerConfig())
    m = built.model
    groups = sorted({g for g in m.row_groups if g.startswith("task:") and "pillar" in g})
    assert len(groups) == 2
    for group in groups:
        robot = re.search(r"!in\((R\d), pillar\)", group).group(1)
        used = {m.col_names[i] for row, g in zip(m.rows, m.row_groups) if g == group for i in row[0]}
        names = {n for n in used if n.startswith("!in(")}
        assert names and all(n.startswith(f"!in({robot},pillar)@") for n in names), (group, sorted(names))
