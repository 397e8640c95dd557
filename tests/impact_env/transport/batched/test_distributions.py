"""Random-action episodes under 5 % thrust noise and 5 cm start noise: the final robustness of the batched
world and of the pymunk env have the same distribution (two-sample Kolmogorov-Smirnov test, alpha = 0.01).

The two draw their noise from different generators (Philox against numpy), so only distributions can
agree. The functions are :mod:`benchmarks.batched_parity`'s (1,000 episodes per scenario there): 30 episodes
of two short scenarios in the default suite, 200 of every shipped scenario in the slow suite; the p-values are
printed."""

from __future__ import annotations

import pytest

from benchmarks.batched_parity import ALPHA, compare
from impact_env.transport.scenario import scenario_names

FAST = ("throw_and_catch_exp", "two_objects")  # the shortest horizons, one with two objects


def check(name: str, episodes: int) -> None:
    cell = compare(name, episodes)
    print(f"{name}: KS p = {cell['ks_pvalue']:.3f} ({episodes} episodes each; mean final robustness "
          f"pymunk {cell['pymunk_mean_m']:.3f} m, batched {cell['batched_mean_m']:.3f} m)")
    assert cell["ks_pvalue"] > ALPHA


@pytest.mark.parametrize("name", FAST)
def test_final_robustness_distribution_matches_pymunk(name):
    check(name, 30)


@pytest.mark.slow
@pytest.mark.parametrize("name", scenario_names())
def test_final_robustness_distribution_matches_pymunk_200_episodes(name):
    check(name, 200)


def test_draws_are_independent_replications_and_the_table_combines_them():
    from benchmarks.batched_parity import batched_finals, key_of, pymunk_finals, replications

    # draw 0 is the benchmark's published seeds; another draw flies other episodes on both sides
    assert not (pymunk_finals("throw_and_catch_exp", 3) == pymunk_finals("throw_and_catch_exp", 3, draw=1)).all()
    assert not (batched_finals("throw_and_catch_exp", 3) == batched_finals("throw_and_catch_exp", 3, draw=1)).all()
    old = {"scenario": "s", "episodes": 10, "ks_pvalue": 0.004}  # a cell written before draws existed
    assert key_of(old) == ("s", 10, 0)
    cells = [old] + [dict(old, draw=d, ks_pvalue=p) for d, p in ((1, 0.5), (2, 0.02), (3, 0.005))]
    row = replications(cells).splitlines()[2]
    assert "| s | 10 | 3 | 0.500, 0.020, 0.005 | 2 of 3 |" in row  # draw 0 is not one of the replications
    assert replications([old]) == ""


def test_holm_adjustment_against_its_definition():
    from benchmarks.batched_parity import holm

    # m = 4: sorted 0.01, 0.02, 0.03, 0.5 -> 0.04, max(0.04, 0.06), max(0.06, 0.06), max(0.06, 0.5)
    assert holm([0.03, 0.5, 0.01, 0.02]) == pytest.approx([0.06, 0.5, 0.04, 0.06])
    assert holm([0.9, 0.8]) == [1.0, 1.0]
