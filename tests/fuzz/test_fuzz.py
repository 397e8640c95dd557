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

import functools
import json
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import impact_env
from impact_env.envs import TransportEnv
from impact_env.stl import parse, robustness
from impact_env.transport.scenario import load_scenario, scenario_from_dict
from planners.plan import Plan
from tests.fuzz.invariant import (
    assert_finite,
    assert_inside,
    attempt,
    cpu_deadline,
    fly,
    fuzz_fixed,
    fuzz_for_budget,
)

# Everything below that needs hypothesis (tests/fuzz/strategies.py), a scenario or an environment is made when
# a fuzzer first runs, not when the suite is collected.
STEPS = 12  # control periods flown per accepted scenario or option set
DEFAULT_EXAMPLES = {"scenario_bytes": 150, "scenario_tree": 200, "stl_text": 400, "plan_file": 150, "gym_action": 300,
                    "pettingzoo_action": 300, "env_options": 100}
_TRACE = {"O1": np.linspace([1.0, 2.0], [1.0, 8.0], 31), "R1": np.tile([1.0, 1.0], (31, 1)),
          "R2": np.tile([1.0, 9.0], (31, 1))}


@functools.cache
def _tmp() -> Path:
    """The folder the scenario-file fuzzer writes its files into (removed at the end of the module)."""
    return Path(tempfile.mkdtemp(prefix="impact_env_fuzz_"))


@functools.cache
def _regions() -> dict:
    return load_scenario("corridor").region_map()


def teardown_module() -> None:
    if _tmp.cache_info().currsize:
        shutil.rmtree(_tmp(), ignore_errors=True)


def fly_scenario(scenario) -> None:
    """An accepted scenario must build an environment and fly: no typed error is excused here."""
    with cpu_deadline():
        fly(TransportEnv(scenario), steps=STEPS)


# ------------------------------------------------------------------------------------------- properties


def scenario_bytes(args: tuple[str, bytes]) -> None:
    name, data = args
    path = _tmp() / f"{name}.toml"
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
    rho = attempt("stl_text", lambda: robustness(formula, _TRACE, _regions(), dt=0.1))
    if rho is not None:
        assert not np.isnan(rho), f"robustness of {text!r} is NaN"
    from tests.fuzz import strategies as S

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


@functools.cache
def _gym() -> TransportEnv:
    return TransportEnv("corridor")


@functools.cache
def _pz():
    return impact_env.parallel_env(scenario="corridor")


def gym_action(action: Any) -> None:
    env = _gym()
    env.reset(seed=0)
    result = attempt("gym_action", lambda: env.step(action))
    if result is not None:
        obs, reward, *_ = result
        assert_finite(obs, "observation")
        assert_finite(reward, "reward")
        assert_inside(env)


def pettingzoo_action(actions: Any) -> None:
    par = _pz()
    par.reset(seed=0)
    result = attempt("pettingzoo_action", lambda: par.step(actions))
    if result is not None:
        observations, rewards, *_ = result
        for agent in observations:
            assert_finite(observations[agent], f"observation of {agent}")
            assert_finite(rewards[agent], f"reward of {agent}")
        assert_inside(par)


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


@functools.cache
def fuzzers() -> dict[str, tuple[Any, Callable[[Any], None]]]:
    """Each fuzzer's name -> (its hypothesis strategy, the property every drawn input must have)."""
    from hypothesis import strategies as st

    from tests.fuzz import strategies as S

    scenario_names = st.sampled_from(S.SCENARIOS)
    plans = st.sampled_from(sorted(S.PLANS))
    found = {
        "scenario_bytes": (scenario_names.flatmap(lambda n: st.tuples(st.just(n), S.mutated_bytes(S.TEXTS[n]))),
                           scenario_bytes),
        "scenario_tree": (scenario_names.flatmap(lambda n: S.mutated_tree(S.DICTS[n], toml_safe=True)),
                          scenario_tree),
        "stl_text": (S.stl_texts(), stl_text),
        "plan_file": (plans.flatmap(lambda n: st.tuples(st.just(n), S.mutated_tree(S.PLANS[n]))), plan_file),
        "gym_action": (S.actions, gym_action),
        "pettingzoo_action": (S.agent_actions, pettingzoo_action),
        "env_options": (st.tuples(scenario_names, S.env_options), env_options),
    }
    assert sorted(found) == sorted(DEFAULT_EXAMPLES), "every fuzzer needs its DEFAULT_EXAMPLES"
    return found


@pytest.mark.parametrize("name", sorted(DEFAULT_EXAMPLES))
def test_fuzz(name):
    fuzz_fixed(name, *fuzzers()[name], DEFAULT_EXAMPLES[name])


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(DEFAULT_EXAMPLES))
def test_fuzz_long(name):
    fuzz_for_budget(name, *fuzzers()[name], 200)
