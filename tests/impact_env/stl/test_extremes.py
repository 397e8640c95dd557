"""STL text at its extremes: long runs of white space, bounds at the edge of float, and what each gives.

Regression tests of issue 24: the tokenizer was quadratic in a run of white space before the end (20,000
trailing spaces took 87 s), and ``robustness(parse('F[0,1e308] ...'))`` raised ``OverflowError``.
"""

from __future__ import annotations

import numpy as np
import pytest

from impact_env.errors import STLError, STLSyntaxError
from impact_env.stl import OnlineMonitor, horizon_steps, interval_steps, parse, robustness
from impact_env.stl.formula import Eventually, InRegion
from impact_env.transport.scenario import load_scenario

REGIONS = load_scenario("corridor").region_map()
TRACE = {"O1": np.linspace([1.0, 2.0], [1.0, 8.0], 31)}


@pytest.mark.timeout(60)  # the quadratic tokenizer would take hours on these; the linear one milliseconds
@pytest.mark.parametrize("text", [
    "in(O1, goal)" + " " * 1_000_000,
    " " * 1_000_000 + "in(O1, goal)",
    "in(O1," + "\t\n " * 300_000 + "goal)",
])
def test_white_space_runs_parse(text):
    assert parse(text) == InRegion("O1", "goal")


@pytest.mark.timeout(60)
@pytest.mark.parametrize("text, column", [
    ("in(O1, goal)" + " " * 1_000_000 + "~", 1_000_012),
    ("in(O1, goal)" + " " * 1_000_000 + "& " + " " * 1_000_000, None),
    (" " * 1_000_000, None),
])
def test_white_space_runs_before_an_error(text, column):
    with pytest.raises(STLSyntaxError) as info:
        parse(text)
    if column is not None:
        assert info.value.column == column and "unknown token '~'" in str(info.value)


def test_tokens_keep_their_columns():
    with pytest.raises(STLSyntaxError) as info:
        parse("  in(O1, goal)   %")
    assert info.value.column == 17
    assert parse("   F[0,1]   in(O1,goal)   ") == Eventually(0.0, 1.0, InRegion("O1", "goal"))


@pytest.mark.parametrize("text, expected", [
    ("F[0,1e308] in(O1, goal)", 0.75),  # the object reaches the goal's edge region by the trace's end
    ("F[1e308,1e308] in(O1, goal)", 0.75),  # beyond the end: the held last sample
    ("G[0,1.7976931348623157e308] !in(O1, goal)", -0.75),
    ("in(O1, goal) U[0,1e308] in(O1, goal)", None),
    ("F[0,1e20] in(O1, goal)", 0.75),
])
def test_robustness_of_huge_bounds_is_finite(text, expected):
    rho = robustness(parse(text), TRACE, REGIONS, dt=0.1)
    assert np.isfinite(rho)
    if expected is not None:
        assert rho == pytest.approx(expected)
    assert rho == robustness(parse(text.replace("1e308", "1e6").replace("1.7976931348623157e308", "1e6")),
                             TRACE, REGIONS, dt=0.1)


@pytest.mark.parametrize("text", ["F[0,1e308] in(O1, goal)", "G[0,1e308] in(O1, goal)",
                                  "in(O1, goal) U[0,1e308] in(O1, goal)"])
def test_sample_counts_of_huge_bounds_are_typed_errors(text):
    """Only the offline robustness can cap a bound at the trace; a monitor or a horizon needs the count."""
    formula = parse(text)
    with pytest.raises(STLError, match="too long for dt"):
        horizon_steps(formula, 0.1)
    with pytest.raises(STLError, match="too long for dt"):
        OnlineMonitor(formula, REGIONS, 0.1)
    with pytest.raises(STLError, match="overflows"):
        interval_steps(0.0, 1e308, 0.1)


def test_a_scenario_with_a_huge_bound_is_a_scenario_error():
    from impact_env.errors import ScenarioError
    from impact_env.transport.scenario import scenario_from_dict
    from tests.fuzz.strategies import DICTS

    with pytest.raises((ScenarioError, STLError)):
        scenario_from_dict(DICTS["corridor"] | {"task": "F[0,1e308] in(O1, goal)"})


@pytest.mark.parametrize("number", ["1e308", "1.7976931348623157e308", "4.9e-324", "0.0000000000000000001", "1e-400"])
def test_number_extremes_parse_and_print_back(number):
    formula = parse(f"F[0,{number}] in(O1, goal)")
    assert parse(str(formula)) == formula


@pytest.mark.parametrize("number", ["1e309", "9" * 400])
def test_bounds_beyond_float_are_syntax_errors(number):
    with pytest.raises(STLSyntaxError, match="finite"):
        parse(f"F[0,{number}] in(O1, goal)")
