"""Property-based fuzzing of everything a user hands in: scenario files (bytes, numbers, structure), STL text,
plan files, actions of both environments and environment options.

The invariant (tests/fuzz/invariant.py): every input works or raises one of the package's typed errors within
a CPU-time deadline, and what works produces finite numbers and keeps every body inside the world.

Two sizes. The default run (``make test``) tries :data:`DEFAULT_EXAMPLES` inputs per fuzzer, derandomized,
so it is fast and the same on every machine. The slow run keeps drawing fresh inputs for
``IMPACT_ENV_FUZZ_SECONDS`` seconds per fuzzer (default 60) and prints how many it tried::

    IMPACT_ENV_FUZZ_SECONDS=120 .venv/bin/python -m pytest -m slow tests/fuzz -n 2

(``make fuzz`` runs it for about 10 minutes on two processes and prints the table of inputs tried.)
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
import time
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, seed, settings
from hypothesis import strategies as st

import impact_env
from impact_env.envs import TransportEnv
from impact_env.stl import parse, robustness
from impact_env.transport.scenario import load_scenario, scenario_from_dict
from planners.plan import Plan
from tests.fuzz import strategies as S
from tests.fuzz.invariant import COUNTS, assert_finite, assert_inside, attempt, cpu_deadline, fly

_TMP = Path(tempfile.mkdtemp(prefix="impact_env_fuzz_"))
STEPS = 12  # control periods flown per accepted scenario or option set
DEFAULT_EXAMPLES = {"scenario_bytes": 150, "scenario_tree": 200, "stl_text": 400, "plan_file": 150, "gym_action": 300,
                    "pettingzoo_action": 300, "env_options": 100}
_TRACE = {"O1": np.linspace([1.0, 2.0], [1.0, 8.0], 31), "R1": np.tile([1.0, 1.0], (31, 1)),
          "R2": np.tile([1.0, 9.0], (31, 1))}
_REGIONS = load_scenario("corridor").region_map()


def teardown_module() -> None:
    shutil.rmtree(_TMP, ignore_errors=True)


def fly_scenario(scenario) -> None:
    """An accepted scenario must build an environment and fly: no typed error is excused here."""
    with cpu_deadline():
        fly(TransportEnv(scenario), steps=STEPS)


# ------------------------------------------------------------------------------------------- properties


def scenario_bytes(args: tuple[str, bytes]) -> None:
    name, data = args
    path = _TMP / f"{name}.toml"
    path.write_bytes(data)
    scenario = attempt("scenario_bytes", lambda: load_scenario(path))
    if scenario is not None:
        fly_scenario(scenario)


def scenario_tree(tree: dict) -> None:
    scenario = attempt("scenario_tree", lambda: scenario_from_dict(tree))
    if scenario is not None:
        fly_scenario(scenario)


def stl_text(text: str) -> None:
    formula = attempt("stl_text", lambda: parse(text))
    if formula is None:
        return
    assert parse(str(formula)) == formula, f"{text!r} printed as {str(formula)!r} parses differently"
    rho = attempt("stl_text", lambda: robustness(formula, _TRACE, _REGIONS, dt=0.1))
    if rho is not None:
        assert not np.isnan(rho), f"robustness of {text!r} is NaN"
    task = S.DICTS["corridor"] | {"task": text}
    scenario = attempt("stl_text", lambda: scenario_from_dict(task))
    if scenario is not None:
        fly_scenario(scenario)


def plan_file(args: tuple[str, dict]) -> None:
    name, tree = args
    scenario = load_scenario(name.split("__")[0])  # "corridor" or "corridor__ir_plan"

    def load() -> Plan:
        plan = Plan.from_dict(json.loads(json.dumps(tree)))  # through JSON, as a file would be
        plan.check(scenario, tol=1e-5)
        return plan

    plan = attempt("plan_file", load)
    if plan is not None:
        t = np.linspace(0.0, scenario.tf_s, 51)
        for body in plan.bodies:
            assert_finite(plan.position(body, t), f"{body} position")
            assert_finite(plan.velocity(body, t), f"{body} velocity")


_GYM = TransportEnv("corridor")
_PZ = impact_env.parallel_env(scenario="corridor")


def gym_action(action: Any) -> None:
    _GYM.reset(seed=0)
    result = attempt("gym_action", lambda: _GYM.step(action))
    if result is not None:
        obs, reward, *_ = result
        assert_finite(obs, "observation")
        assert_finite(reward, "reward")
        assert_inside(_GYM)


def pettingzoo_action(actions: Any) -> None:
    _PZ.reset(seed=0)
    result = attempt("pettingzoo_action", lambda: _PZ.step(actions))
    if result is not None:
        observations, rewards, *_ = result
        for agent in observations:
            assert_finite(observations[agent], f"observation of {agent}")
            assert_finite(rewards[agent], f"reward of {agent}")
        assert_inside(_PZ)


def env_options(args: tuple[str, dict]) -> None:
    name, options = args
    env = attempt("env_options", lambda: TransportEnv(name, **options))
    if env is not None:
        with cpu_deadline():
            fly(env, steps=STEPS, seed=1)
    par = attempt("env_options", lambda: impact_env.parallel_env(scenario=name, **options))
    if par is not None:
        with cpu_deadline():
            par.reset(seed=2)
            for _ in range(3):
                _, rewards, *_ = par.step({a: np.ones(3) for a in par.agents})
                assert_finite(list(rewards.values()), "rewards")
                assert_inside(par)


scenario_names = st.sampled_from(S.SCENARIOS)
FUZZERS: dict[str, tuple[st.SearchStrategy, Callable[[Any], None]]] = {
    "scenario_bytes": (scenario_names.flatmap(lambda n: st.tuples(st.just(n), S.mutated_bytes(S.TEXTS[n]))),
                       scenario_bytes),
    "scenario_tree": (scenario_names.flatmap(lambda n: S.mutated_tree(S.DICTS[n], toml_safe=True)), scenario_tree),
    "stl_text": (S.stl_texts(), stl_text),
    "plan_file": (st.sampled_from(sorted(S.PLANS)).flatmap(lambda n: st.tuples(st.just(n), S.mutated_tree(S.PLANS[n]))),
                  plan_file),
    "gym_action": (S.actions, gym_action),
    "pettingzoo_action": (S.agent_actions, pettingzoo_action),
    "env_options": (st.tuples(scenario_names, S.env_options), env_options),
}


def hypothesis_test(name: str, max_examples: int, seed_value: int | None = None) -> Callable[[], None]:
    strategy, prop = FUZZERS[name]

    def counted(value: Any) -> None:
        COUNTS.setdefault(name, Counter())["inputs"] += 1
        prop(value)

    test = settings(max_examples=max_examples, deadline=None, database=None, derandomize=seed_value is None,
                    suppress_health_check=list(HealthCheck), print_blob=True)(given(strategy)(counted))
    return test if seed_value is None else seed(seed_value)(test)


@pytest.mark.parametrize("name", sorted(FUZZERS))
def test_fuzz(name):
    hypothesis_test(name, DEFAULT_EXAMPLES[name])()
    assert COUNTS[name]["inputs"] >= DEFAULT_EXAMPLES[name]
    _report(name, COUNTS[name], slow=False)


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(FUZZERS))
def test_fuzz_long(name):
    budget = float(os.environ.get("IMPACT_ENV_FUZZ_SECONDS", "60"))
    start = time.monotonic()
    round_ = 0
    while time.monotonic() - start < budget:
        hypothesis_test(name, 200, seed_value=int(time.time_ns() % 2 ** 32) + round_)()
        round_ += 1
    _report(name, COUNTS[name], slow=True, seconds=time.monotonic() - start)


def _report(name: str, counts, slow: bool, seconds: float | None = None) -> None:
    """One JSON line per fuzzer in IMPACT_ENV_FUZZ_REPORT (if set); tests/fuzz/conftest.py prints the table."""
    path = os.environ.get("IMPACT_ENV_FUZZ_REPORT")
    if path:
        with open(path, "a") as f:
            f.write(json.dumps({"fuzzer": name, "slow": slow, "seconds": seconds, **counts}) + "\n")
