"""The two substep kernels give the same numbers: the fused one (what torch.compile fuses, run here in
eager) against the reference, bit for bit, and the eager free-flight shortcut against full substeps; a
polygon obstacle against the pymunk world. The compiled kernels are checked in the slow suite."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import pytest

from impact_env.transport.core import TransportCore
from impact_env.transport.scenario import Scenario, load_scenario, scenario_from_dict
from tests.helpers import two_body_dict

if TYPE_CHECKING:
    import torch


def with_polygon() -> Scenario:
    """A robot, two objects and a triangular obstacle with a slanted face."""
    data = two_body_dict(robot_pos=(2.0, 2.0), robot_vel=(0.2, 0.25), object_pos=(6.0, 3.0), object_vel=(0.0, 0.0))
    data["objects"].append(dict(data["objects"][0], name="O2", position_m=[3.0, 7.0], velocity_mps=[0.3, 0.0]))
    data["obstacles"] = [{"name": "wedge", "polygon": [[5.0, 5.0], [8.0, 5.5], [6.0, 8.0]]}]
    data["tf_s"] = 30.0
    data["task"] = "F[0,30] in(O1, goal) & G[0,30] !in(O2, wedge)"
    return scenario_from_dict(data)


def random_rows(scene, layout, n: int, dtype, gen) -> torch.Tensor:
    """Bodies anywhere in the world box (overlapping walls, obstacles and each other) with random velocities."""
    import torch

    rows = torch.zeros(layout.n_rows, n, dtype=dtype)
    xmin, xmax, ymin, ymax = scene.world_box
    B = scene.n_bodies
    rows[:B] = torch.rand(B, n, generator=gen, dtype=dtype) * (xmax - xmin) + xmin
    rows[B:2 * B] = torch.rand(B, n, generator=gen, dtype=dtype) * (ymax - ymin) + ymin
    rows[2 * B:4 * B] = torch.randn(2 * B, n, generator=gen, dtype=dtype) * 0.3
    return rows


@pytest.mark.parametrize("dtype", ["float32", "float64"])
@pytest.mark.parametrize("name", ["corridor", "two_objects", "polygon"])
def test_fused_kernel_equals_the_reference_bit_for_bit(name, dtype):
    import torch

    from impact_env.transport.batched.fused import FusedKernel
    from impact_env.transport.batched.physics import ReferenceKernel
    from impact_env.transport.batched.scene import PolygonShape, build_scene

    dtype = getattr(torch, dtype)
    sc = with_polygon() if name == "polygon" else load_scenario(name)
    scene = build_scene(sc)
    assert (name == "polygon") == any(isinstance(o, PolygonShape) for o in scene.obstacles)
    ref, fused = ReferenceKernel(scene, torch.device("cpu"), dtype), FusedKernel(scene, dtype)
    gen = torch.Generator().manual_seed(1)
    n = 512
    rows = random_rows(scene, ref.layout, n, dtype, gen)
    ended = torch.zeros(ref.layout.n_contacts, n, dtype=dtype)
    noise = torch.rand(len(scene.robot_object_pairs), 2, n, generator=gen, dtype=dtype) * 0.1
    compared = flagged = 0
    for _ in range(100):
        force = torch.randn(2, scene.n_robots, n, generator=gen, dtype=dtype) * 3.0
        a_rows, a_ended = ref.substep(rows, ended, force, noise)
        b_rows, b_ended, redo = fused.substep(rows, ended, force, noise)
        keep = ~redo
        assert torch.equal(a_rows[:, keep], b_rows[:, keep]) and torch.equal(a_ended[:, keep], b_ended[:, keep])
        compared += int(keep.sum())
        flagged += int(redo.sum())
        rows, ended = a_rows, a_ended
    assert flagged > 0 and int(ended.sum()) > 300 and compared > 10_000  # contacts of every kind


@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_free_flight_shortcut_equals_the_substeps(dtype):
    import torch

    from impact_env.transport.batched.physics import ReferenceKernel
    from impact_env.transport.batched.scene import build_scene

    dtype = getattr(torch, dtype)
    scene = build_scene(load_scenario("obstacle_avoidance"))
    ref = ReferenceKernel(scene, torch.device("cpu"), dtype)
    gen = torch.Generator().manual_seed(2)
    rows = torch.zeros(ref.layout.n_rows, 64, dtype=dtype)
    B = scene.n_bodies
    for b in range(B):
        rows[b], rows[B + b] = scene.position_m[b]
    rows[2 * B:4 * B] = torch.randn(2 * B, 64, generator=gen, dtype=dtype) * 0.05
    force = torch.randn(2, scene.substeps, scene.n_robots, 64, generator=gen, dtype=dtype)
    assert ref.clear_of_contacts(rows, torch.full((scene.n_robots, 64), 2.0, dtype=dtype), 0.1)
    stepped = rows
    ended = torch.zeros(ref.layout.n_contacts, 64, dtype=dtype)
    for s in range(scene.substeps):
        stepped, ended = ref.substep(stepped, ended, force[:, s], None)
    assert torch.equal(ref.free_flight(rows, force), stepped) and not ended.any()
    touching = rows.clone()
    touching[0, 3] = scene.world_box[0] + scene.radius_m[0] + 1e-3  # 1 mm from the left wall
    assert not ref.clear_of_contacts(touching, torch.full((scene.n_robots, 64), 2.0, dtype=dtype), 0.1)


def test_polygon_obstacle_follows_the_pymunk_world():
    import torch

    from impact_env.transport.batched import BatchedTransportWorld

    sc = with_polygon()
    core = TransportCore(sc)
    core.reset(np.random.default_rng(0))
    world = BatchedTransportWorld(sc, 1, dtype=torch.float64)
    world.reset(seeds=0)
    rng = np.random.default_rng(3)
    impacts = {}
    for _ in range(core.horizon_steps):
        a = rng.uniform(-0.3, 0.3, world.action_size)
        _, _, info = core.step(a)
        for event in info["impacts"]:
            impacts[frozenset((event["a"], event["b"]))] = impacts.get(frozenset((event["a"], event["b"])), 0) + 1
        world.step(torch.tensor(a[None]))
        np.testing.assert_allclose(world.body_state()[0].numpy(), np.array(core.world.read_state()), atol=1e-9)
    assert impacts.get(frozenset(("O2", "wedge")), 0) >= 1  # the slanted face was hit


@pytest.mark.slow
def test_compiled_world_follows_the_eager_world():
    """torch.compile (inductor) against eager, float64, two_objects with every noise: the same trajectory to
    rounding (inductor may contract or reorder a few operations), and the same impacts."""
    import torch

    from impact_env.transport.batched import BatchedTransportWorld

    kwargs = {"dtype": torch.float64, "thrust_noise": 0.05, "initial_position_noise_m": 0.05,
              "impact_velocity_noise_mps": 0.02}
    eager = BatchedTransportWorld("two_objects", 64, **kwargs)
    compiled = BatchedTransportWorld("two_objects", 64, compile=True, **kwargs)
    eager.reset(seeds=0)
    compiled.reset(seeds=0)
    gen = torch.Generator().manual_seed(0)
    impacts = 0
    for _ in range(eager.horizon_steps):
        a = torch.rand(64, eager.action_size, generator=gen) * 2.4 - 1.2
        o1, r1, _, _, i1 = eager.step(a)
        o2, r2, _, _, i2 = compiled.step(a)
        impacts += int(i1["impacts"].sum())
    diverged = (eager.body_state() - compiled.body_state()).abs().amax(dim=(1, 2)) > 1e-6
    assert impacts > 100 and int(diverged.sum()) <= 2  # chaotic amplification of rounding in a rare env
    np.testing.assert_allclose(i1["robustness"][~diverged].numpy(), i2["robustness"][~diverged].numpy(), atol=1e-6)


def test_blocks_of_envs_give_the_whole_batchs_results():
    """The compiled world runs its kernels on blocks of envs (world.in_chunks); here in eager, blocks of 7."""
    import torch

    from impact_env.transport.batched import BatchedTransportWorld
    from impact_env.transport.batched.world import in_chunks

    world = BatchedTransportWorld("two_objects", 30, dtype=torch.float64, thrust_noise=0.1,
                                  impact_velocity_noise_mps=0.02)
    world.reset(seeds=0)
    for k in range(4):
        a = torch.rand(30, world.action_size, generator=torch.Generator().manual_seed(k)) * 2.4 - 1.2
        args = (a, world.ang, world.omg, world._key[0], world._key[1], world.step_count, world.episodes, world.rows)
        whole = world._fused_period_impl(*args)
        blocks = in_chunks(world._fused_period_impl, args, 30, batch_first_in=(0,), chunk=7)
        for x, y in zip(whole, blocks):
            assert torch.equal(x, y)
        epilogue = (whole[7], whole[3], whole[4], world.step_count + 1, world.monitor.state, world._potential,
                    world.fuel_Ns, whole[1], whole[8], world.last_impact_step)
        for x, y in zip(world._epilogue_impl(*epilogue), in_chunks(world._epilogue_impl, epilogue, 30,
                                                                   batch_first_out=(0,), chunk=7)):
            assert all(torch.equal(u, v) for u, v in zip(x, y)) if isinstance(x, tuple) else torch.equal(x, y)
        world.step(a)
