"""Property-based fuzzing of the tether world's inputs: station files (bytes, numbers and structure), tether
plans, actions of both tether environments and their options (faults among them).

The invariant of tests/fuzz/invariant.py: every input works or raises one of the package's typed errors within
the CPU-time deadline, and what works produces finite numbers and keeps the cargo inside its station's bounding
box. An accepted station must build both environments and fly (random commands, holds and releases included)
under every fidelity; an accepted plan must be flown by the expert. Sizes as in test_fuzz.py: the default run
tries :data:`DEFAULT_EXAMPLES` derandomized inputs per fuzzer, ``-m slow`` draws fresh ones for
``IMPACT_ENV_FUZZ_SECONDS`` per fuzzer (``make fuzz``).
"""

from __future__ import annotations

import copy
import json
import math
import shutil
import sys
import tempfile
from collections.abc import Callable
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import strategies as st

from impact_env.tether.gym_env import TetherEnv
from impact_env.tether.pettingzoo_env import TetherParallelEnv
from impact_env.tether.station import load_station, station_from_dict, station_names
from planners.tether.expert import TetherExpert
from planners.tether.plan import TetherPlan
from tests.fuzz import strategies as S
from tests.fuzz.invariant import assert_finite, attempt, cpu_deadline, fuzz_fixed, fuzz_for_budget
from tests.paths import DATA

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

STATIONS = tuple(station_names())
TEXTS = {n: resources.files("impact_env.tether.stations").joinpath(f"{n}.toml").read_text() for n in STATIONS}
DICTS = {n: tomllib.loads(t) for n, t in TEXTS.items()}
PLANS_DIR = DATA / "plans" / "tether"
PLANS = {p.stem: json.loads(p.read_text()) for p in sorted(PLANS_DIR.glob("*.json"))}
STEPS = 8  # control periods flown per accepted station, per fidelity
DEFAULT_EXAMPLES = {"station_bytes": 60, "station_tree": 80, "tether_plan": 40, "tether_gym_action": 150,
                    "tether_pettingzoo_action": 150, "tether_env_options": 40}
_TMP = Path(tempfile.mkdtemp(prefix="impact_env_tether_fuzz_"))


def teardown_module() -> None:
    shutil.rmtree(_TMP, ignore_errors=True)


def assert_cargo_inside(env: Any) -> None:
    core = env.unwrapped.core if hasattr(env, "unwrapped") else env.core
    xmin, xmax, ymin, ymax = core.station.bounds
    x, y, vx, vy = core.world.state()
    assert_finite([x, y, vx, vy], "cargo state")
    assert xmin - 1e-3 <= x <= xmax + 1e-3 and ymin - 1e-3 <= y <= ymax + 1e-3, \
        f"cargo at ({x}, {y}) is outside the station's box {core.station.bounds}"


def fly_tether(env: Any, steps: int = STEPS, seed: int = 0) -> None:
    """Reset and step with random commands (attaches, releases, holds, keeps), checking the invariant."""
    obs, info = env.reset(seed=seed)
    assert_finite(obs, "observation at reset")
    assert math.isfinite(info["robustness"])
    rng = np.random.default_rng(seed)
    n = env.action_space.nvec
    for _ in range(steps):
        action = np.array([rng.integers(0, k) for k in n])
        obs, reward, terminated, truncated, info = env.step(action)
        assert_finite(obs, "observation")
        assert math.isfinite(reward), f"reward {reward}"
        assert math.isfinite(info["robustness"]) and math.isfinite(info["winch_work_J"])
        assert env.observation_space.contains(obs), "observation outside its space"
        assert_cargo_inside(env)
        if terminated or truncated:
            break


def fly_station(station: Any) -> None:
    """An accepted station must build the environments and fly under every fidelity: no error is excused."""
    with cpu_deadline():
        for fidelity in ("kinematic", "reel", "force"):
            fly_tether(TetherEnv(station, fidelity=fidelity), steps=STEPS)
        par = TetherParallelEnv(station)
        par.reset(seed=1)
        _, rewards, *_ = par.step({a: 2 for a in par.agents})
        assert_finite(list(rewards.values()), "rewards")


# ------------------------------------------------------------------------------------------- properties


def station_bytes(args: tuple[str, bytes]) -> None:
    name, data = args
    path = _TMP / f"{name}.toml"
    path.write_bytes(data)
    station = attempt("station_bytes", lambda: load_station(path))
    if station is not None:
        fly_station(station)


def station_tree(tree: dict) -> None:
    station = attempt("station_tree", lambda: station_from_dict(tree))
    if station is not None:
        fly_station(station)


_STATION_OBJECTS = {n: load_station(n) for n in STATIONS}


def tether_plan(args: tuple[str, dict]) -> None:
    name, tree = args
    station = _STATION_OBJECTS[name]

    def load() -> TetherExpert:
        plan = TetherPlan.from_dict(json.loads(json.dumps(tree)))  # through JSON, as a file would be
        return TetherExpert(station, plan=plan)  # checks the plan

    expert = attempt("tether_plan", load)
    if expert is not None:
        with cpu_deadline():
            env = TetherEnv(station)
            obs, info = env.reset(seed=0)
            expert.reset(env)
            for _ in range(STEPS):
                obs, reward, *_, info = env.step(expert.act(obs, info))
                assert_finite(obs, "observation")
                assert math.isfinite(reward)


_GYM = TetherEnv("L", fidelity="reel")
_PZ = TetherParallelEnv("L", fidelity="reel")


def tether_gym_action(action: Any) -> None:
    _GYM.reset(seed=0)
    result = attempt("tether_gym_action", lambda: _GYM.step(action))
    if result is not None:
        obs, reward, *_ = result
        assert_finite(obs, "observation")
        assert_finite(reward, "reward")
        assert_cargo_inside(_GYM)


def tether_pettingzoo_action(actions: Any) -> None:
    _PZ.reset(seed=0)
    result = attempt("tether_pettingzoo_action", lambda: _PZ.step(actions))
    if result is not None:
        observations, rewards, *_ = result
        for agent in observations:
            assert_finite(observations[agent], f"observation of {agent}")
            assert_finite(rewards[agent], f"reward of {agent}")
        assert_cargo_inside(_PZ)


def tether_env_options(args: tuple[str, dict]) -> None:
    name, options = args
    env = attempt("tether_env_options", lambda: TetherEnv(name, **options))
    if env is not None:
        with cpu_deadline():
            fly_tether(env, steps=STEPS, seed=3)


# ------------------------------------------------------------------------------------------- strategies

station_names_st = st.sampled_from(STATIONS)


@st.composite
def station_variants(draw) -> dict:
    """A shipped station's tree with 1-4 edits, or one of the shapes that once broke the loader: a huge anchor
    count, huge coordinates, thousands of vertices, a million robots, a billion substeps, a horizon below one
    control period, a constant task, a goal a subnormal wide."""
    name = draw(station_names_st)
    base = copy.deepcopy(DICTS[name])
    kind = draw(st.sampled_from(["mutate"] * 6 + ["known"]))
    if kind == "mutate":
        return draw(S.mutated_tree(base, toml_safe=True))
    edit = draw(st.sampled_from(["spacing", "coords", "vertices", "robots", "substeps", "horizon", "task", "goal",
                                 "hold", "names"]))
    if edit == "spacing":
        base["anchors"] = {"spacing_m": draw(st.sampled_from([1e-6, 1e-3, 0.01, 5e-324, 1e-300]))}
    elif edit == "coords":
        scale = draw(st.sampled_from([1e155, 1e5, 1e4, 1e300]))
        base["station"]["polygon"] = [[x * scale, y * scale] for x, y in base["station"]["polygon"]]
    elif edit == "vertices":
        n = draw(st.sampled_from([499, 500, 501, 5000]))
        angles = np.linspace(0, 2 * np.pi, n, endpoint=False)
        base["station"]["polygon"] = np.stack([10 + 8 * np.cos(angles), 10 + 8 * np.sin(angles)], 1).tolist()
        base["cargo"]["start_m"], base["goal"] = [10.0, 10.0], {"center_m": [12.0, 10.0], "half_size_m": 0.5}
        base["anchors"] = {"spacing_m": 2.5}
    elif edit == "robots":
        base["robots"]["count"] = draw(st.sampled_from([10 ** 6, 33, 32, 0]))
        base["robots"].pop("max_active", None)
    elif edit == "substeps":
        base["substeps"] = draw(st.sampled_from([10 ** 9, 1001, 1000]))
    elif edit == "horizon":
        base["tf_s"], base["control_period_s"] = draw(st.sampled_from([(0.5, 1.0), (1.0, 1.0), (2.0, 1.0)]))
        base["goal"]["hold_s"] = 0.0
    elif edit == "task":
        base["task"] = draw(st.sampled_from(["G[0,600] false", "F[0,600] true", "G[0,600] true", "F[0,0.5] false",
                                             "F[0,600] in(drift, rest)", "G[0,600] !in(cargo, goal)"]))
    elif edit == "goal":
        base["goal"] = {"center_m": base["goal"]["center_m"],
                        "half_size_m": draw(st.sampled_from([1e-300, 5e-324, 1e-4, 1e-3]))}
    elif edit == "hold":
        base["goal"]["hold_s"] = draw(S.numbers)
    else:
        base["robots"]["names"] = draw(st.sampled_from([["R1", "R2", "R3"], ["a", "a", "b"], ["x"], [1, 2, 3]]))
    return base


@st.composite
def tether_actions(draw) -> Any:
    top = _GYM.core.n_commands
    good = st.lists(st.integers(0, top - 1), min_size=3, max_size=3)
    kind = draw(st.sampled_from(["good", "good", "numpy", "bad"]))
    if kind == "good":
        return draw(good)
    if kind == "numpy":
        return np.array(draw(good), dtype=draw(st.sampled_from(["int64", "int8", "uint8", "float32", "float64"])))
    return draw(st.one_of(S.numpy_actions(), S.python_actions, st.lists(S.numbers, min_size=3, max_size=3)))


@st.composite
def tether_agent_actions(draw) -> Any:
    top = _PZ.core.n_commands
    agents = list(_PZ.possible_agents)
    kind = draw(st.sampled_from(["good", "good", "bad"]))
    if kind == "good":
        return draw(st.dictionaries(st.sampled_from(agents), st.one_of(st.none(), st.integers(0, top - 1),
                                                                      st.integers(0, top - 1).map(np.int64)),
                                    max_size=3))
    return draw(st.one_of(
        st.dictionaries(st.sampled_from(agents + ["robot_0", "R9", ""]), st.one_of(S.numpy_actions(),
                                                                                 S.python_actions), max_size=3),
        S.python_actions, S.numpy_actions(), st.none()))


fault_values = st.one_of(S.numbers, st.integers(0, 3), st.tuples(S.numbers, S.numbers),
                         st.sampled_from([(0.1, 0.3), (0.0, 0.95), (10.0, 150.0), (150.0, 10.0)]))
tether_options = st.fixed_dictionaries({}, optional={
    "fidelity": st.sampled_from(["kinematic", "reel", "force", "Reel", ""]),
    "reward_mode": st.sampled_from(["dense", "sparse", "shaped"]),
    "energy_penalty": S.option_numbers,
    "pull_speed_mps": st.one_of(st.none(), S.option_numbers, st.sampled_from([0.05, 0.09, 0.11, 0.2, 1.0])),
    "max_active": st.one_of(st.none(), st.integers(-1, 5), st.sampled_from([1.5, True])),
    "initial_position_noise_m": st.one_of(S.option_numbers, st.sampled_from([0.3, 3.0])),
    "faults": st.one_of(st.none(), st.sampled_from([{"anchor_failures": 1}, {"tether_snaps": 2},
                                                    {"robot_dropouts": 1}, {"robot_dropouts": 3},
                                                    {"winch_speed_error": (0.1, 0.3)}, {"window_s": (0.0, 5.0),
                                                                                        "anchor_failures": 3}]),
                        st.dictionaries(st.sampled_from(["anchor_failures", "tether_snaps", "robot_dropouts",
                                                         "winch_speed_error", "window_s", "bogus"]),
                                        fault_values, max_size=3), S.python_actions),
})

FUZZERS: dict[str, tuple[st.SearchStrategy, Callable[[Any], None]]] = {
    "station_bytes": (station_names_st.flatmap(lambda n: st.tuples(st.just(n), S.mutated_bytes(TEXTS[n]))),
                      station_bytes),
    "station_tree": (station_variants(), station_tree),
    "tether_plan": (st.sampled_from(sorted(PLANS)).flatmap(lambda n: st.tuples(st.just(n),
                                                                               S.mutated_tree(PLANS[n]))),
                    tether_plan),
    "tether_gym_action": (tether_actions(), tether_gym_action),
    "tether_pettingzoo_action": (tether_agent_actions(), tether_pettingzoo_action),
    "tether_env_options": (st.tuples(station_names_st, tether_options), tether_env_options),
}


@pytest.mark.parametrize("name", sorted(FUZZERS))
def test_tether_fuzz(name):
    fuzz_fixed(name, *FUZZERS[name], DEFAULT_EXAMPLES[name])


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(FUZZERS))
def test_tether_fuzz_long(name):
    fuzz_for_budget(name, *FUZZERS[name], 100)
