"""The tether world's compiled kinematic loop (impact_env.tether.native) against its Python loops, bit for bit:
whole expert episodes on every shipped station (with faults, too), scripted episodes with holds, delays and
winch speed errors, and the uncached wall test; the loop's hypot against math.hypot. The Python loops run in
this process with the compiled loop switched off (as when it is not built), and once in a fresh process under
IMPACT_ENV_PURE_PYTHON=1."""

from __future__ import annotations

import hashlib
import math
import os
import random
import subprocess
import sys

import numpy as np
import pytest

from impact_env.tether import native
from impact_env.tether.gym_env import TetherEnv
from impact_env.tether.physics import TetherWorld
from impact_env.tether.station import load_station, station_names
from planners.tether.expert import TetherExpert

pytestmark = pytest.mark.skipif(not native.available(), reason="the compiled tether loop is not built")


python_loop = native.disabled


def test_the_loops_hypot_is_pythons():
    from impact_env.tether import _substeps

    rng = random.Random(11)
    pairs = native.hypot_sample(20_000, seed=3)
    pairs += [(rng.uniform(-60, 60), rng.uniform(-60, 60)) for _ in range(200_000)]  # station-sized
    pairs += [(rng.uniform(-1, 1) * 1e-9, rng.uniform(-1, 1)) for _ in range(20_000)]  # very unequal sides
    pairs += [(math.inf, math.nan), (math.nan, 1.0), (-math.inf, 2.0), (5e-324, 5e-324)]
    for x, y in pairs:
        got, want = _substeps.hypot(x, y), math.hypot(x, y)
        assert got == want or (math.isnan(got) and math.isnan(want)), (x, y, got, want)


def _expert_episode(station: str, seed: int, compiled: bool, **env) -> tuple[str, int, float]:
    """Digest of every observation, reward and info of one expert episode with every cargo state, its length
    and the winch work; ``compiled``: whether the world must run the compiled loop."""
    e = TetherEnv(station, fidelity="kinematic", **env)
    obs, info = e.reset(seed=seed)
    expert = TetherExpert(e.station)
    expert.reset(e, seed)
    h, steps, done = hashlib.sha256(), 0, False
    while not done:
        obs, reward, terminated, truncated, info = e.step(expert.act(obs, info))
        done = terminated or truncated
        steps += 1
        h.update(obs.tobytes() + np.array(e.core.world.state()).tobytes())
        h.update(repr((reward, terminated, truncated, sorted(info.items()))).encode())
    assert (e.core.world._kinematic_loop is not None) == compiled
    return h.hexdigest(), steps, e.core.world.winch_work_J


@pytest.mark.parametrize("name", station_names())
def test_the_compiled_loop_flies_every_shipped_station_as_the_python_loop(name):
    compiled = _expert_episode(name, 2, True)
    with python_loop():
        python = _expert_episode(name, 2, False)
    assert compiled == python and compiled[1] > 10


@pytest.mark.parametrize("name", ["L", "iss_chain"])
def test_faults_fly_the_same_through_both_loops(name):
    faults = {"anchor_failures": 1, "tether_snaps": 1, "winch_speed_error": (0.1, 0.3), "window_s": (5.0, 40.0)}
    compiled = _expert_episode(name, 4, True, faults=faults)
    with python_loop():
        python = _expert_episode(name, 4, False, faults=faults)
    assert compiled == python


def _scripted(world: TetherWorld, station, seed: int) -> str:
    """Random attachments (some delayed), releases and holds every 12 steps, 180 steps."""
    rng, h = np.random.default_rng(seed), hashlib.sha256()
    robots = min(3, station.n_robots)
    for step in range(180):
        if step % 12 == 0:
            los = np.flatnonzero(station.line_of_sight(world.position_m))
            for robot in range(robots):
                if world.tether_anchor(robot) is not None and rng.uniform() < 0.4:
                    world.release(robot)
                if world.tether_anchor(robot) is None and len(los):
                    a = int(rng.choice(los))
                    if a not in [world.tether_anchor(r) for r in range(station.n_robots)]:
                        world.attach(robot, a, delay_s=float(rng.choice([0.0, 0.35, 2.0])))
                if rng.uniform() < 0.2:
                    world.hold(robot)
                elif rng.uniform() < 0.2:
                    world.reel(robot)
        for e in world.step():
            h.update(repr(e.to_dict()).encode())
        h.update(np.array(world.state()).tobytes() + repr((world.winch_work_J, world.wall_contacts)).encode())
    return h.hexdigest()


@pytest.mark.parametrize("cache", [True, False])
@pytest.mark.parametrize("name", station_names())
def test_scripted_holds_delays_and_winch_errors_fly_the_same_through_every_loop(name, cache):
    station = load_station(name)
    speeds = [0.1 * (1.0 + 0.1 * k) for k in range(station.n_robots)]  # a winch speed error on all but robot 0

    def world(fast: bool) -> TetherWorld:
        return TetherWorld(station, "kinematic", cache_checks=cache, winch_speeds_mps=speeds, fast=fast)

    compiled = world(True)
    assert compiled._kinematic_loop is not None
    digests = [_scripted(compiled, station, 5), _scripted(compiled.restart(winch_speeds_mps=speeds), station, 6)]
    with python_loop():
        cffi = world(True)
        assert cffi._kinematic_loop is None and cffi._fast
        python = [_scripted(cffi, station, 5), _scripted(cffi.restart(winch_speeds_mps=speeds), station, 6)]
    public = world(False)
    assert public._kinematic_loop is None and not public._fast
    assert digests == python == [_scripted(public, station, 5), _scripted(public.restart(winch_speeds_mps=speeds),
                                                                          station, 6)]


def test_the_loop_checks_its_plan():
    world = TetherWorld(load_station("L"), "kinematic")
    loop = world._kinematic_loop
    with pytest.raises(TypeError, match="lists"):
        loop.set_plan((1.0, 2.0), 0.1, None, [], True)
    with pytest.raises(ValueError, match="2 numbers"):
        loop.set_plan([(1.0, 2.0, 3.0)], 0.1, None, [], True)
    with pytest.raises(ValueError, match="one speed per"):
        loop.set_plan([(1.0, 2.0)], 0.1, [0.1, 0.2], [], True)
    with pytest.raises(TypeError, match="10 arguments"):
        loop.run(1, 0)


def test_pure_python_requested_runs_the_python_loop():
    code = ("from impact_env.tether import native; from impact_env.tether.physics import TetherWorld; "
            "from impact_env.tether.station import load_station; "
            "w = TetherWorld(load_station('L'), 'kinematic'); print(native.available(), w._kinematic_loop)")
    env = {**os.environ, "IMPACT_ENV_PURE_PYTHON": "1"}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "None"]
