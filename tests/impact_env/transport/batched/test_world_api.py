"""BatchedTransportWorld's API: shapes, views, rewards, errors, partial resets and rendering."""

from __future__ import annotations

import subprocess
import sys
from typing import TYPE_CHECKING

import numpy as np
import pytest

from impact_env.envs import TransportEnv
from impact_env.errors import ActionError, EnvConfigError, ImpactEnvError, STLUnsupportedError
from impact_env.stl import conjuncts, robustness
from impact_env.transport.core import TransportCore
from impact_env.transport.scenario import load_scenario, scenario_from_dict
from tests.helpers import two_body_dict

if TYPE_CHECKING:
    import torch


def random_actions(world, seed: int) -> torch.Tensor:
    import torch

    return torch.rand(world.num_envs, world.action_size, generator=torch.Generator().manual_seed(seed)) * 2 - 1


def test_shapes_and_views():
    import torch

    from impact_env.transport.batched import BatchedTransportWorld

    world = BatchedTransportWorld("two_objects", 5)
    obs = world.reset(seeds=3)
    B, R = world.n_bodies, world.n_robots
    assert obs.shape == (5, 7 * B + 1) and obs.dtype == torch.float32 and world.action_size == 3 * R
    obs, reward, term, trunc, info = world.step(random_actions(world, 0))
    assert reward.shape == (5,) and reward.dtype == torch.float32 and term.dtype == torch.bool and not trunc.any()
    assert set(info) == {"robustness", "is_success", "fuel_Ns", "time_s", "impacts"}
    assert info["impacts"].dtype == torch.int64 and torch.equal(info["is_success"], info["robustness"] > 0)
    assert torch.equal(world.state(), obs)
    agents = world.agent_observations()
    assert agents.shape == (5, R, 7 * B + 1)
    assert torch.equal(agents[:, 0], obs)  # robot 0 is body 0: its view is the central one
    assert torch.equal(agents[:, 1, :7], obs[:, 7:14]) and torch.equal(agents[:, 1, 7:14], obs[:, :7])
    assert torch.equal(agents[:, 1, 14:], obs[:, 14:])
    assert world.body_state().shape == (5, B, 6)
    np.testing.assert_allclose(info["time_s"].numpy(), 0.1, rtol=1e-6)


def test_agent_observations_match_the_core():
    import torch

    from impact_env.transport.batched import BatchedTransportWorld

    core = TransportCore("relay")
    core.reset(np.random.default_rng(0))
    world = BatchedTransportWorld("relay", 1, dtype=torch.float64)
    world.reset(seeds=0)
    for k in range(30):
        a = random_actions(world, k).double()
        core.step(a[0].numpy())
        world.step(a)
    for r in range(world.n_robots):
        np.testing.assert_allclose(world.agent_observations()[0, r].numpy(), core.agent_observation(r), atol=1e-6)


@pytest.mark.parametrize("mode", ["dense", "sparse", "conjuncts"])
def test_rewards_sum_to_the_offline_robustness_of_the_trace(mode):
    """dense and sparse: to the task's robustness; conjuncts: to the mean of its conjuncts' (offline, numpy)."""
    import torch

    from impact_env.transport.batched import BatchedTransportWorld

    world = BatchedTransportWorld("ping_pong_stop", 4, dtype=torch.float64, reward_mode=mode)
    world.reset(seeds=0)
    trace = [world.body_state()[:, :, :2].numpy()]
    total = torch.zeros(4, dtype=torch.float64)
    for k in range(world.horizon_steps):
        _, reward, term, _, info = world.step(random_actions(world, k))
        if mode == "sparse" and k < world.horizon_steps - 1:
            assert not reward.any()
        total += reward
        trace.append(world.body_state()[:, :, :2].numpy())
    assert term.all()
    trace = np.stack(trace)  # [T, N, B, 2]
    sc = world.scenario
    parts = conjuncts(sc.formula) if mode == "conjuncts" else (sc.formula,)
    for env in range(4):
        signals = {name: trace[:, env, b] for b, name in enumerate(world.body_names)}
        offline = np.mean([robustness(f, signals, sc.region_map(), sc.control_period_s) for f in parts])
        assert float(total[env]) == pytest.approx(offline, abs=1e-12)
    if mode != "conjuncts":
        np.testing.assert_allclose(total.numpy(), info["robustness"].numpy(), atol=1e-12)


def test_fuel_penalty_is_subtracted_per_step():
    import torch

    from impact_env.transport.batched import BatchedTransportWorld

    plain = BatchedTransportWorld("corridor", 3, dtype=torch.float64)
    taxed = BatchedTransportWorld("corridor", 3, dtype=torch.float64, fuel_penalty=0.5)
    plain.reset(seeds=1), taxed.reset(seeds=1)
    a = random_actions(plain, 0)
    _, r0, _, _, info0 = plain.step(a)
    _, r1, _, _, info1 = taxed.step(a)
    fuel = 0.1 * ((a.double().reshape(3, 2, 3)[:, :, :2].clamp(-1, 1) * 2.8) ** 2).sum(-1).sqrt()  # |F| dt
    np.testing.assert_allclose((r0 - r1).numpy(), 0.5 * info1["fuel_Ns"].numpy(), rtol=1e-12)
    np.testing.assert_allclose(info0["fuel_Ns"].numpy(), fuel.sum(1).numpy(), rtol=1e-12)


def test_robustness_of_a_task_that_always_holds_is_clipped():
    import torch

    from impact_env.transport.batched import BatchedTransportWorld

    data = two_body_dict()
    data["task"] = "F[0,2] true"
    sc = scenario_from_dict(data)
    world = BatchedTransportWorld(sc, 2, dtype=torch.float64)
    world.reset(seeds=0)
    _, reward, _, _, info = world.step(torch.zeros(2, 3))
    assert torch.all(info["robustness"] == TransportCore(sc).robustness_limit_m)
    assert torch.isfinite(reward).all()


def test_bad_actions_and_states_are_typed_errors():
    import torch

    from impact_env.transport.batched import BatchedTransportWorld

    world = BatchedTransportWorld("corridor", 4)
    with pytest.raises(ImpactEnvError, match="reset"):
        world.step(torch.zeros(4, 6))
    world.reset(seeds=0)
    bad = torch.zeros(4, 6)
    bad[2, 1] = float("nan")
    with pytest.raises(ActionError, match=r"envs \[2\]"):
        world.step(bad)
    for shape in ((4, 5), (3, 6), (4, 3, 2)):
        with pytest.raises(ActionError, match="shape"):
            world.step(torch.zeros(shape))
    with pytest.raises(ActionError):
        world.step("left")
    assert int(world.step_count[0]) == 0  # nothing was stepped
    world.step(torch.zeros(4, 2, 3))  # (N, R, 3) is accepted too


@pytest.mark.parametrize("kwargs,match", [
    ({"num_envs": 0}, "num_envs"), ({"reward_mode": "shaped"}, "reward_mode"), ({"dtype": "float16"}, "dtype"),
    ({"contact_iterations": 0}, "contact_iterations"), ({"thrust_noise": -1.0}, "thrust_noise"),
    ({"restitution": 1.5}, "restitution"), ({"device": "nonsense"}, "device"),
    ({"initial_position_noise_m": 50.0}, "initial_position_noise_m"),
])
def test_bad_options_are_typed_errors(kwargs, match):
    import torch

    from impact_env.transport.batched import BatchedTransportWorld

    if "dtype" in kwargs:  # named at collection, the torch dtype here
        kwargs = {**kwargs, "dtype": getattr(torch, kwargs["dtype"])}
    args = {"num_envs": 2, **kwargs}
    with pytest.raises(EnvConfigError, match=match):
        BatchedTransportWorld("corridor", **args)


def test_bad_seeds_and_masks_are_typed_errors():
    import torch

    from impact_env.transport.batched import BatchedTransportWorld

    world = BatchedTransportWorld("corridor", 3)
    for seeds in ([1, 2], [-1, 0, 1], [0.5, 1, 2], [True, 1, 2]):
        with pytest.raises(EnvConfigError, match="seeds"):
            world.reset(seeds=seeds)
    with pytest.raises(EnvConfigError, match="mask"):
        world.reset(mask=torch.ones(2, dtype=torch.bool))


def test_the_horizon_ends_an_env_and_a_partial_reset_restarts_only_it():
    import torch

    from impact_env.transport.batched import BatchedTransportWorld

    world = BatchedTransportWorld("throw_and_catch_exp", 3, dtype=torch.float64)
    world.reset(seeds=[5, 6, 7])
    for k in range(world.horizon_steps):
        _, _, term, _, _ = world.step(random_actions(world, k))
    assert term.all()
    with pytest.raises(ImpactEnvError, match="horizon"):
        world.step(torch.zeros(3, 6))
    kept = world.body_state()[1:].clone()
    mask = torch.tensor([True, False, False])
    world.reset(mask=mask)
    assert torch.equal(world.body_state()[1:], kept) and world.step_count.tolist() == [0, 200, 200]
    assert world.episodes.tolist() == [1, 0, 0]
    fresh = BatchedTransportWorld("throw_and_catch_exp", 1, dtype=torch.float64)
    assert torch.equal(world.observation()[0], fresh.reset(seeds=0)[0])  # no noise: the scenario's start
    world.reset(mask=~mask)  # the horizon check is per env: everything can step again
    world.step(torch.zeros(3, 6))


def test_rgb_frames_are_the_gym_envs_frames():
    import torch

    from impact_env.transport.batched import BatchedTransportWorld

    env = TransportEnv("corridor", render_mode="rgb_array", render_width_px=200)
    world = BatchedTransportWorld("corridor", 2, dtype=torch.float64)
    env.reset(seed=0)
    world.reset(seeds=0)
    frames = [(env.render(), world.render_rgb(1, width_px=200))]
    for k in range(5):
        a = random_actions(world, k)
        env.step(a[1].numpy())
        world.step(a)
    frames.append((env.render(), world.render_rgb(1, width_px=200)))
    for ref, got in frames:
        assert got.dtype == np.uint8 and got.shape == ref.shape
        assert np.array_equal(got, ref)
    with pytest.raises(EnvConfigError, match="env_index"):
        world.render_rgb(2)


def test_importing_the_package_does_not_import_torch():
    code = "import sys, impact_env, impact_env.envs, impact_env.transport; assert 'torch' not in sys.modules"
    subprocess.run([sys.executable, "-c", code], check=True)


def test_scenario_objects_and_files_are_accepted():
    from impact_env.transport.batched import BatchedTransportWorld

    sc = load_scenario("relay")
    world = BatchedTransportWorld(sc, 2)
    assert world.scenario is sc and world.horizon_steps == 600


def test_a_task_outside_the_monitors_class_is_refused_when_the_world_is_built():
    from impact_env.transport.batched import BatchedTransportWorld

    data = two_body_dict()
    data["task"] = "F[0,10] G[0,5] in(O1, goal)"
    sc = scenario_from_dict(data)
    TransportCore(sc)  # the scalar monitor handles nesting
    with pytest.raises(STLUnsupportedError, match="nests"):
        BatchedTransportWorld(sc, 2)
