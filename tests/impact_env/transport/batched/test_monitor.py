"""The batched STL monitor equals one scalar OnlineMonitor per env, on random traces."""

from __future__ import annotations

import numpy as np
import pytest

from impact_env.errors import STLUnsupportedError
from impact_env.stl import OnlineMonitor, conjuncts, parse
from impact_env.transport.scenario import load_scenario
from tests.impact_env.transport.batched.backends import shipped_scenarios

TOLERANCE = {"float64": 1e-12, "float32": 1e-5}  # by torch dtype name


def random_traces(sc, steps: int, n: int, seed: int) -> np.ndarray:
    """[steps, 2, B, n] smooth random walks over the world box (m)."""
    rng = np.random.default_rng(seed)
    xmin, xmax, ymin, ymax = sc.world_box
    B = len(sc.bodies)
    start = np.stack([rng.uniform(xmin, xmax, (B, n)), rng.uniform(ymin, ymax, (B, n))])
    walk = np.cumsum(rng.normal(0.0, 0.08, (steps, 2, B, n)), axis=0)
    return start + walk


def compare(sc, formulas, dtype_name: str, starts=None, seed=0, n=6) -> float:
    """Largest |batched - scalar| over a random trace, the batched monitor in torch's ``dtype_name``; env i
    starts its episode at step starts[i]."""
    import torch

    from impact_env.transport.batched.monitor import BatchedMonitor

    dtype = getattr(torch, dtype_name)
    names = [b.name for b in sc.bodies]
    dt = sc.control_period_s
    monitor = BatchedMonitor(formulas, sc.region_map(), dt, names, n, torch.device("cpu"), dtype)
    horizon = max(monitor.horizons)
    starts = np.zeros(n, dtype=int) if starts is None else np.asarray(starts)
    trace = random_traces(sc, horizon + 1 + int(starts.max()), n, seed)
    if dtype == torch.float32:
        trace = trace.astype(np.float32).astype(np.float64)  # both read the same positions
    scalar = [[OnlineMonitor(f, sc.region_map(), dt) for f in formulas] for _ in range(n)]
    worst = 0.0
    for t in range(trace.shape[0]):
        k = t - starts
        active = (k >= 0) & (k <= horizon)
        mask = torch.tensor(active)
        if t in set(starts.tolist()):
            monitor.reset(torch.tensor(k == 0))
        values = monitor.update(torch.tensor(trace[t], dtype=dtype), torch.tensor(np.maximum(k, 0)), mask)
        for env in np.flatnonzero(active):
            positions = {name: (trace[t, 0, b, env], trace[t, 1, b, env]) for b, name in enumerate(names)}
            for f, mon in enumerate(scalar[env]):
                expected = mon.update(positions)
                got = float(values[f, env])
                if np.isinf(expected):
                    assert got == expected
                else:
                    worst = max(worst, abs(got - expected))
    return worst


@pytest.mark.parametrize("dtype", ["float64", "float32"])
# the default suite: windows that start late, negations, five conjuncts (every task in the slow suite)
@pytest.mark.parametrize("name", shipped_scenarios(("ping_pong_stop", "two_objects", "timed_visits")))
def test_shipped_tasks_and_their_conjuncts(name, dtype):
    sc = load_scenario(name)
    formulas = [sc.formula, *conjuncts(sc.formula)]
    assert compare(sc, formulas, dtype) <= TOLERANCE[dtype]


@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_envs_at_different_steps_of_their_episodes(dtype):
    sc = load_scenario("relay")
    assert compare(sc, [sc.formula], dtype, starts=[0, 3, 17, 40, 41, 90]) <= TOLERANCE[dtype]


@pytest.mark.parametrize("text", [
    "in(R1, A) U[2,12] in(O1, B)",
    "!(F[0,5] in(O1, A) | G[3,9] !in(R2, C)) & F[1,20] (in(O1, B) | in(R1, C))",
    "in(O1, A) | F[0,0] in(R1, B) | G[4,6] in(R3, C)",
    "(in(R1, A) & !in(O1, B)) U[0,0] in(R2, C) & F[0,10] true",
    "G[0,10] false | F[2,8] in(O1, A)",
    "!(in(R1, A) U[5,10] (in(O1, B) & !in(R2, A)))",
])
@pytest.mark.parametrize("dtype", ["float64", "float32"])
def test_other_formulas_of_the_supported_class(text, dtype):
    assert compare(load_scenario("relay"), [parse(text)], dtype, seed=3) <= TOLERANCE[dtype]


@pytest.mark.parametrize("text", ["F[0,10] G[0,5] in(O1, A)", "G[0,10] (in(R1, A) U[0,3] in(O1, B))",
                                  "F[0,5] !(F[0,2] in(O1, A))"])
def test_nested_temporal_operators_are_a_typed_error(text):
    import torch

    from impact_env.transport.batched.monitor import BatchedMonitor

    sc = load_scenario("relay")
    with pytest.raises(STLUnsupportedError, match="nests"):
        BatchedMonitor([parse(text)], sc.region_map(), 0.1, [b.name for b in sc.bodies], 2, torch.device("cpu"),
                       torch.float32)
