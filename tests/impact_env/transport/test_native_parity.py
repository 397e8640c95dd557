"""The compiled paths of the impact world (impact_env.transport.native: substep loop, action scaling,
observations, PettingZoo dicts; impact_env.stl.compiled) against the pure-Python paths, bit for bit: the same
trajectories, impact logs, observations, rewards and infos, the same errors, and no buffer shared between what
two steps return. The Python paths run in this process with the compiled helpers switched off (as when they are
not built), and once in a fresh process under IMPACT_ENV_PURE_PYTHON=1."""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
import warnings

import numpy as np
import pytest

import impact_env.stl.compiled as compiled
from impact_env import native as native_loader
from impact_env.errors import ActionError
from impact_env.transport import native
from impact_env.transport.core import TransportCore
from impact_env.transport.gym_env import TransportEnv
from impact_env.transport.pettingzoo_env import TransportParallelEnv
from impact_env.transport.physics import World
from impact_env.transport.scenario import load_scenario, scenario_from_dict, scenario_names
from tests.helpers import two_body_dict

pytestmark = pytest.mark.skipif(not native.available() or compiled._cmonitor is None,
                                reason="the compiled helpers are not built")


@contextlib.contextmanager
def python_paths():
    """Every compiled helper off, as in a build without them (objects made inside use the Python paths)."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(native, "_ADDRESSES", None)
        mp.setattr(native, "Observer", None)
        mp.setattr(native, "parallel_outputs", None)
        mp.setattr(compiled, "_cmonitor", None)
        yield


def _actions(n_robots: int, steps: int, seed: int = 0) -> np.ndarray:
    """Random actions, some beyond [-1, 1] (clipped), float32 as a policy gives them."""
    return np.random.default_rng(seed).uniform(-1.3, 1.3, (steps, 3 * n_robots)).astype(np.float32)


# ------------------------------------------------------------------------------------------------ the world
@pytest.mark.parametrize("name", scenario_names())
def test_the_compiled_loop_flies_every_shipped_scenario_as_the_public_api(name):
    sc = load_scenario(name)
    lim = np.array([[*r.thrust_limit_N, r.torque_limit_Nm] for r in sc.robots])
    rng = np.random.default_rng(5)
    wrenches = [[tuple(w) for w in rng.uniform(-1, 1, (len(sc.robots), 3)) * lim] for _ in range(400)]
    noise = {"impact_velocity_noise_mps": 0.03}
    compiled_world = World(sc, rng=np.random.default_rng(1), **noise)
    public = World(sc, fast=False, rng=np.random.default_rng(1), **noise)
    with python_paths():
        cffi = World(sc, rng=np.random.default_rng(1), **noise)
    assert compiled_world._loop is not None and public._loop is None and cffi._loop is None and cffi._fast
    worlds = (compiled_world, public, cffi)
    events = [[], [], []]
    for w in wrenches:
        for i, world in enumerate(worlds):
            events[i] += world.step(w)
        states = [world.read_state() for world in worlds]
        assert states[0] == states[1] == states[2]
        assert compiled_world.n_substeps_done == public.n_substeps_done == cffi.n_substeps_done
    for i in range(3):
        events[i] += worlds[i].flush_impacts()
    assert [e.to_dict() for e in events[0]] == [e.to_dict() for e in events[1]] == [e.to_dict() for e in events[2]]


def test_contacts_ending_in_one_substep_are_closed_between_compiled_runs_in_the_scenarios_order():
    """Two impacts that end in the same substep, many substeps per control period: the loop stops after that
    substep, the World closes both in the scenario's order (and draws their noise), then goes on."""
    data = two_body_dict(e=0.75, robot_pos=(2.0, 3.0), object_pos=(4.0, 3.0), control_period_s=0.1, substeps=10)
    data["robots"].append({**data["robots"][0], "name": "R2", "position_m": [2.0, 7.0]})
    data["objects"].append({**data["objects"][0], "name": "O2", "position_m": [4.0, 7.0]})
    sc = scenario_from_dict(data)
    worlds = [World(sc, fast=fast, impact_velocity_noise_mps=0.05, rng=np.random.default_rng(7))
              for fast in (True, False)]
    events = [[], []]
    for _ in range(100):
        for i, world in enumerate(worlds):
            events[i] += world.step([(0.0, 0.0, 0.0)] * 2)
        assert worlds[0].read_state() == worlds[1].read_state()
    assert [(e.a, e.b) for e in events[0]][:2] == [("R1", "O1"), ("R2", "O2")]
    assert [e.to_dict() for e in events[0]] == [e.to_dict() for e in events[1]]


def test_the_world_clock_and_wrench_buffer_of_the_compiled_loop():
    sc = load_scenario("corridor")
    world = World(sc)
    world.step([(1.0, 0.5, 0.1), (0.0, -1.0, 0.0)])
    assert world.n_substeps_done == sc.substeps and world.time_s == sc.substeps * world.dt_s
    assert world.wrench.tolist() == [[1.0, 0.5, 0.1], [0.0, -1.0, 0.0]]
    world.n_substeps_done += 1  # tests/replay.py steps the space itself and counts
    assert world.n_substeps_done == sc.substeps + 1
    world.wrench[0] = (2.0, 0.0, 0.0)  # step() without wrenches flies the buffer
    world.step()
    out = np.empty((len(sc.bodies), 6))
    world.read_state_into(out)
    assert [tuple(r) for r in out.tolist()] == world.read_state()


# ------------------------------------------------------------------------------------------------ the envs
def _gym_record(env: TransportEnv, actions, episodes: int = 2, seed: int = 3) -> list:
    out = []
    obs, info = env.reset(seed=seed)
    out.append((obs.tobytes(), sorted(info.items())))
    held = obs  # what a caller keeps must not change under it
    held_copy = obs.copy()
    k = done = 0
    while done < episodes:
        obs, reward, terminated, truncated, info = env.step(actions[k % len(actions)])
        k += 1
        assert obs.dtype == np.float32 and env.observation_space.contains(obs)
        out.append((obs.tobytes(), reward, terminated, truncated, repr(sorted(info.items()))))
        if terminated or truncated:
            done += 1
            obs, info = env.reset()
            out.append((obs.tobytes(), sorted(info.items())))
    assert held.tobytes() == held_copy.tobytes()
    core = env.unwrapped.core
    out.append((core._state, core.last_wrenches, core.log.fuel_Ns, [e.to_dict() for e in core.log.impacts]))
    return out


CASES = [
    ("corridor", {}),
    ("corridor", {"reward_mode": "sparse", "fuel_penalty": 0.3}),
    ("two_objects", {"reward_mode": "conjuncts", "thrust_noise": 0.1, "initial_position_noise_m": 0.1}),
    ("relay", {"impact_velocity_noise_mps": 0.05, "restitution": 0.6}),
    ("ping_pong_stop", {"thrust_noise": 0.2}),
]


@pytest.mark.parametrize("name,kwargs", CASES, ids=[f"{n}-{'-'.join(k) or 'default'}" for n, k in CASES])
def test_the_gym_env_returns_the_same_episodes_on_both_paths(name, kwargs):
    sc = load_scenario(name)
    actions = _actions(len(sc.robots), 300)
    fast = TransportEnv(sc, **kwargs)
    assert fast.unwrapped.core._observer is not None
    assert type(fast.unwrapped.core.monitor) is compiled.CompiledMonitor
    record = _gym_record(fast, actions)
    with python_paths():
        slow = TransportEnv(sc, **kwargs)
        core = slow.unwrapped.core
        assert core._observer is None and type(core.monitor) is not compiled.CompiledMonitor
        assert record == _gym_record(slow, actions)


def _pz_record(env: TransportParallelEnv, actions, seed: int = 4) -> list:
    agents = env.possible_agents
    out = []
    observations, infos = env.reset(seed=seed)
    out.append(({a: o.tobytes() for a, o in observations.items()}, infos))
    kept = observations
    kept_bytes = {a: o.tobytes() for a, o in observations.items()}
    k = 0
    while env.agents:
        act = actions[k % len(actions)]
        if k % 7 == 3:  # an agent left out (zero thrust), or given None, or lists, ints: the slower readers
            joint = {agents[0]: act[:3]}
        elif k % 7 == 4:
            joint = {a: None if i == 0 else act[3 * i: 3 * i + 3] for i, a in enumerate(agents)}
        elif k % 7 == 5:
            joint = {a: act[3 * i: 3 * i + 3].tolist() for i, a in enumerate(agents)}
        elif k % 7 == 6:
            joint = {a: np.array([1, -2, 0]) for a in agents}
        else:
            joint = {a: act[3 * i: 3 * i + 3] for i, a in enumerate(agents)}
        k += 1
        observations, rewards, terms, truncs, infos = env.step(joint)
        out.append(({a: o.tobytes() for a, o in observations.items()}, rewards, terms, truncs, repr(infos)))
        assert all(o.dtype == np.float32 for o in observations.values())
        assert list(observations) == list(rewards) == list(infos) == agents
        if len(observations) > 1:  # separate agents' arrays never overlap
            first, second = observations[agents[0]], observations[agents[1]]
            assert not np.shares_memory(first, second)
    assert {a: o.tobytes() for a, o in kept.items()} == kept_bytes
    out.append(env.state().tobytes())
    return out


@pytest.mark.parametrize("name,kwargs", [("corridor", {}), ("relay", {"thrust_noise": 0.1, "max_cycles": 150}),
                                         ("two_objects", {"reward_mode": "conjuncts"})])
def test_the_pettingzoo_env_returns_the_same_dicts_on_both_paths(name, kwargs):
    sc = load_scenario(name)
    actions = _actions(len(sc.robots), 200, seed=1)
    record = _pz_record(TransportParallelEnv(sc, **kwargs), actions)
    with python_paths():
        assert record == _pz_record(TransportParallelEnv(sc, **kwargs), actions)


def test_agent_observations_are_the_central_one_reordered():
    sc = load_scenario("relay")
    env = TransportParallelEnv(sc)
    observations, _ = env.reset(seed=0)
    core = env.core
    for i, agent in enumerate(env.possible_agents):
        order = [i] + [j for j in range(core.n_bodies) if j != i]
        assert observations[agent].tobytes() == core._observe(order).tobytes()
        assert core.agent_observation(i).tobytes() == core._observe(order).tobytes()
    assert core.observation().tobytes() == core._observe(range(core.n_bodies)).tobytes()


BAD_ACTIONS = [np.zeros(5, np.float32), np.zeros((1, 6)), np.zeros((3, 2)), np.array([0, 0, np.nan, 0, 0, 0]),
               [[0.0, 1.0, 0.0], [0.0, 1.0]], "push", np.array([np.inf] * 6, np.float32), [np.zeros(3), np.zeros(2)]]


@pytest.mark.parametrize("action", BAD_ACTIONS, ids=range(len(BAD_ACTIONS)))
def test_a_bad_action_raises_the_same_error_on_both_paths(action):
    def error(core: TransportCore) -> str:
        core.reset(np.random.default_rng(0))
        with pytest.raises(ActionError) as e:
            core.step(action)
        return str(e.value)

    fast = error(TransportCore("corridor"))
    with python_paths():
        assert fast == error(TransportCore("corridor"))


BAD_AGENT_ACTIONS = [{"R1": np.zeros((1, 3))}, {"R1": np.zeros(3, bool)}, {"R9": np.zeros(3)}, ["R1"],
                     {"R1": np.array([0.0, np.nan, 0.0])}, {"R1": "push"}]


@pytest.mark.parametrize("actions", BAD_AGENT_ACTIONS, ids=range(len(BAD_AGENT_ACTIONS)))
def test_a_bad_agent_action_raises_the_same_error_on_both_paths(actions):
    def error() -> str:
        env = TransportParallelEnv("corridor")
        env.reset(seed=0)
        with pytest.raises(ActionError) as e:
            env.step(actions)
        return str(e.value)

    fast = error()
    with python_paths():
        assert fast == error()


def test_stepping_after_the_end_is_refused_before_the_action_is_read_as_before():
    env = TransportParallelEnv("ping_pong_stop")
    env.reset(seed=0)
    while env.agents:
        env.step({})
    with pytest.raises(Exception, match="episode has ended"):
        env.step({a: np.zeros(3) for a in env.possible_agents})
    with pytest.raises(ActionError):  # a malformed action is still named first, as the Python path does
        env.step({"R1": np.zeros(2)})


# ------------------------------------------------------------------------------------------------ fallback
FALLBACK_CHILD = """
import hashlib, json, sys, warnings
import numpy as np
warnings.simplefilter("error")  # switched off on purpose: no note
from impact_env.transport import native
import impact_env.stl.compiled as compiled
from impact_env.transport.gym_env import TransportEnv
env = TransportEnv("corridor", reward_mode="conjuncts", thrust_noise=0.05)
h = hashlib.sha256()
obs, _ = env.reset(seed=2)
acts = np.random.default_rng(0).uniform(-1, 1, (1000, 6)).astype(np.float32)
for k in range(1000):
    obs, r, term, trunc, info = env.step(acts[k])
    h.update(obs.tobytes() + repr((r, term, sorted(info.items()))).encode())
print(json.dumps({"digest": h.hexdigest(), "loop": native.available(), "monitor": compiled._cmonitor is not None,
                  "world": env.unwrapped.core.world._loop is not None}))
"""


def test_the_pure_python_switch_gives_the_same_episode_in_a_fresh_process():
    import hashlib

    env = TransportEnv("corridor", reward_mode="conjuncts", thrust_noise=0.05)
    h = hashlib.sha256()
    env.reset(seed=2)
    acts = np.random.default_rng(0).uniform(-1, 1, (1000, 6)).astype(np.float32)
    for k in range(1000):
        obs, r, term, trunc, info = env.step(acts[k])
        h.update(obs.tobytes() + repr((r, term, sorted(info.items()))).encode())
    done = subprocess.run([sys.executable, "-c", FALLBACK_CHILD], capture_output=True, text=True, check=True,
                          env={**os.environ, native_loader.PURE_PYTHON_VARIABLE: "1"})
    child = json.loads(done.stdout)
    assert child == {"digest": h.hexdigest(), "loop": False, "monitor": False, "world": False}


def test_a_missing_extension_is_one_line_of_warning_and_none():
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert native_loader.load("impact_env.transport._no_such_helper", "the test helper") is None
    assert len(caught) == 1 and caught[0].category is RuntimeWarning
    message = str(caught[0].message)
    assert "\n" not in message and "the test helper runs in pure Python" in message and "same results" in message
