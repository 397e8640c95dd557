"""The batched world (float64) against the pymunk environments, step by step with the same actions."""

from __future__ import annotations

import numpy as np
import pytest

from impact_env.envs import TransportEnv
from impact_env.transport.core import TransportCore
from impact_env.transport.scenario import scenario_from_dict
from tests.helpers import two_body_dict
from tests.impact_env.transport.batched.backends import shipped_scenarios


def far_apart():
    """Two robots and an object 30 m apart in a 150 m box: random thrust never brings them into contact."""
    data = two_body_dict(robot_pos=(60.0, 75.0), robot_vel=(0.0, 0.0), object_pos=(90.0, 75.0),
                         object_vel=(0.05, -0.02), box=(0.0, 150.0, 0.0, 150.0))
    data["robots"].append(dict(data["robots"][0], name="R2", position_m=[75.0, 105.0], heading_rad=1.0,
                               angular_velocity_radps=0.3))
    data["regions"][0]["box"] = [120.0, 130.0, 120.0, 130.0]
    data.update(tf_s=100.0, task="F[0,100] in(O1, goal) & G[0,100] !in(R2, goal)")
    return scenario_from_dict(data)


def test_free_flight_equals_pymunk_to_1e9_m_over_an_episode():
    import torch

    from impact_env.transport.batched import BatchedTransportWorld

    sc = far_apart()
    core = TransportCore(sc)
    core.reset(np.random.default_rng(0))
    world = BatchedTransportWorld(sc, 2, dtype=torch.float64)
    world.reset(seeds=[0, 1])
    rng = np.random.default_rng(5)
    worst = 0.0
    for _ in range(core.horizon_steps):
        a = rng.uniform(-1.0, 1.0, (2, world.action_size))
        _, _, info = core.step(a[0])
        assert info["impacts"] == []
        world.step(torch.tensor(a))
        ref = np.array(core.world.read_state())
        worst = max(worst, float(np.abs(world.body_state()[0].numpy() - ref).max()))
    assert worst < 1e-9
    assert core.step_count == 1000


# the default suite: walls, two objects and a pillar, four robots (the rest in the slow suite)
@pytest.mark.parametrize("name", shipped_scenarios(("wall_start", "two_objects", "four_robots")))
def test_episode_with_impacts_follows_the_pymunk_env(name):
    """Random full-thrust actions for a whole episode: observations, rewards, impacts and fuel as the Gym env's.
    Contacts are resolved alike to rounding, so the trajectories agree to far better than the tolerances."""
    import torch

    from impact_env.transport.batched import BatchedTransportWorld

    mode = {"relay": "conjuncts", "obstacle_avoidance": "sparse"}.get(name, "dense")
    env = TransportEnv(name, reward_mode=mode, fuel_penalty=0.1)
    world = BatchedTransportWorld(name, 1, dtype=torch.float64, reward_mode=mode, fuel_penalty=0.1)
    obs, _ = env.reset(seed=0)
    np.testing.assert_array_equal(world.reset(seeds=0)[0].numpy(), obs)
    rng = np.random.default_rng(1)
    impacts = [0, 0]
    for k in range(env.unwrapped.horizon_steps):
        a = rng.uniform(-1.2, 1.2, env.action_space.shape).astype(np.float32)
        obs, r, term, trunc, info = env.step(a)
        b_obs, b_r, b_term, b_trunc, b_info = world.step(torch.tensor(a[None]))
        np.testing.assert_allclose(b_obs[0].numpy(), obs, atol=1e-5, err_msg=f"step {k}")
        assert float(b_r[0]) == pytest.approx(r, abs=1e-6)
        assert bool(b_term[0]) == term and bool(b_trunc[0]) == trunc
        impacts[0] += len(info["impacts"])
        impacts[1] += int(b_info["impacts"][0])
    assert impacts[0] == impacts[1] > 0
    assert float(b_info["robustness"][0]) == pytest.approx(info["robustness"], abs=1e-6)
    assert float(b_info["fuel_Ns"][0]) == pytest.approx(info["fuel_Ns"], rel=1e-12)
    assert float(b_info["time_s"][0]) == pytest.approx(info["time_s"])
