"""BatchedOneEnv: one env of the batched world with the pymunk env's interface and impact events."""

from __future__ import annotations

import numpy as np
import pytest

from impact_env.envs import TransportEnv
from impact_env.errors import EnvConfigError
from tests.paths import DATA

PLANS = DATA / "plans" / "bench"
VELOCITIES = ("velocity_before", "velocity_after")


def by_body(event: dict) -> dict:
    """An event independent of which body pymunk's arbiter lists first."""
    out = {"time": event["time"], "duration": event["duration"], "pair": frozenset((event["a"], event["b"]))}
    for side in ("a", "b"):
        for key in VELOCITIES:
            out[(event[side], key)] = np.array(event[f"{side}_{key}"])
    return out


def fly_both(name: str, steps: int | None = None, seed: int = 0):
    """(pymunk events, batched events) per step of one full-thrust random episode."""
    from impact_env.transport.batched.one_env import BatchedOneEnv

    ref, env = TransportEnv(name), BatchedOneEnv(name)
    ref.reset(seed=seed)
    env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(steps or env.horizon_steps):
        a = np.sign(rng.uniform(-1, 1, env.action_space.shape)).astype(np.float32)
        _, r_ref, t_ref, _, i_ref = ref.step(a)
        obs, reward, terminated, truncated, info = env.step(a)
        assert terminated == t_ref and not truncated and reward == pytest.approx(r_ref, abs=1e-6)
        assert set(info) == {"robustness", "is_success", "fuel_Ns", "time_s", "impacts"}
        out.append((i_ref["impacts"], info["impacts"]))
    return out


@pytest.mark.parametrize("name", ["two_objects", pytest.param("corridor", marks=pytest.mark.slow),
                                  pytest.param("obstacle_avoidance", marks=pytest.mark.slow)])
def test_impact_events_are_the_pymunk_envs(name):
    """Every event of a full-thrust episode (robot-robot, robot-object, walls, obstacles, and the contacts still
    open at the end): the same pair, step, start time and duration, and velocities within 1e-5 m/s (the
    parity tests' bound on observations: a few dozen impacts amplify the rounding). A few contacts (2 of the
    corridor's 25: an object pushed into a wall) start or end one or two substeps from pymunk's, where the
    gap stays within rounding of zero for several substeps: at most 1 in 10, at most two substeps off. After
    such a contact the two trajectories part (each later impact amplifies the difference about tenfold), so
    the events after it are compared by pair only."""
    substep_s = TransportEnv(name).unwrapped.scenario.physics_dt_s
    total, grazing = 0, 0
    for ref, got in fly_both(name):
        assert len(ref) == len(got)
        for x, y in zip(ref, got):
            x, y = by_body(x), by_body(y)
            assert x["pair"] == y["pair"] and x.keys() == y.keys()
            off = max(abs(x["time"] - y["time"]), abs(x["time"] + x["duration"] - y["time"] - y["duration"]))
            if off > 1e-9:
                assert off <= 2 * substep_s + 1e-9
                grazing += 1
            if grazing:
                continue
            for key in x.keys() - {"time", "duration", "pair"}:
                np.testing.assert_allclose(x[key], y[key], atol=1e-5)
        total += len(ref)
    assert total >= 5 and grazing <= total / 10


def test_separation_velocity_carries_the_post_impact_error():
    """With post-impact velocity noise, a robot-object event's separation velocity of the object is the one it
    flies on (its velocity at the end of the step, when nothing else touched it), off the noiseless world's
    first one by at most the noise per axis."""
    from impact_env.transport.batched.one_env import BatchedOneEnv

    noise = 0.05
    env, quiet = BatchedOneEnv("two_objects", impact_velocity_noise_mps=noise), BatchedOneEnv("two_objects")
    env.reset(seed=3)
    quiet.reset(seed=3)
    objects = {o.name for o in env.scenario.objects}
    robots = {r.name for r in env.scenario.robots}
    names = list(env.world.body_names)
    rng = np.random.default_rng(3)
    checked, first = 0, None
    for _ in range(env.horizon_steps):
        a = np.sign(rng.uniform(-1, 1, env.action_space.shape))
        _, _, _, _, info = env.step(a)
        _, _, _, _, quiet_info = quiet.step(a)
        touched = [n for event in info["impacts"] for n in (event["a"], event["b"])]
        for event in info["impacts"]:
            pair = {event["a"], event["b"]}
            if not (pair & objects and pair & robots):
                continue
            obj = (pair & objects).pop()
            side = "a" if event["a"] == obj else "b"
            if first is None:  # no noise was drawn before: the noiseless world had the same contact
                ref = next(e for e in quiet_info["impacts"] if {e["a"], e["b"]} == pair)
                diff = np.subtract(event[f"{side}_velocity_after"], ref[f"{side}_velocity_after"])
                assert 0 < np.abs(diff).max() <= noise
                first = diff
            if touched.count(obj) == 1 and not env.recorder.open:
                v_now = env.world.body_state()[0, names.index(obj), 2:4].numpy()
                np.testing.assert_allclose(event[f"{side}_velocity_after"], v_now, atol=1e-12)
                checked += 1
        if checked and first is not None:
            break
    assert checked >= 1 and first is not None


def test_options_and_errors():
    import torch

    from impact_env.transport.batched.one_env import BatchedOneEnv

    with pytest.raises(EnvConfigError, match="compile"):
        BatchedOneEnv("corridor", compile=True)
    with pytest.raises(EnvConfigError, match="render_mode"):
        BatchedOneEnv("corridor", render_mode="human")
    env = BatchedOneEnv("corridor", render_mode="rgb_array", render_width_px=80, dtype=torch.float32)
    obs, info = env.reset(seed=0)
    assert obs in env.observation_space and info["impacts"] == [] and info["time_s"] == 0.0
    assert env.render().shape[1] == 80
    with pytest.raises(EnvConfigError, match="options"):
        env.reset(options={"x": 1})
    a, b = BatchedOneEnv("corridor", thrust_noise=0.1), BatchedOneEnv("corridor", thrust_noise=0.1)
    a.reset(seed=4)
    b.reset(seed=4)
    action = np.ones(a.action_space.shape)
    assert np.array_equal(a.step(action)[0], b.step(action)[0])  # same seed, same draws


@pytest.mark.slow
@pytest.mark.parametrize("name", ["throw_and_catch_exp", "corridor"])
def test_the_expert_flies_the_one_env_view_as_the_pymunk_env(name):
    from impact_env.transport.batched.one_env import BatchedOneEnv
    from planners.expert import Expert
    from planners.plan import Plan

    expert = Expert(TransportEnv(name).unwrapped.scenario, plan=Plan.load(PLANS / f"{name}.json"))
    results = []
    for env in (TransportEnv(name), BatchedOneEnv(name)):
        obs, info = env.reset(seed=0)
        expert.reset()
        done = False
        while not done:
            obs, _, terminated, truncated, info = env.step(expert.act(obs, info))
            done = terminated or truncated
        results.append((info["is_success"], info["robustness"], expert.report()["unplanned_contacts"]))
    assert results[0][0] and results[1][0]
    assert results[1][1] == pytest.approx(results[0][1], abs=1e-3)
    assert results[1][2] == results[0][2]
