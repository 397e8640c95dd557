"""The impact-aware MPC (planners/online/mpc.py): its RK4 model against closed forms and pymunk, closed-loop tracking
in the simulator, the impact node, the keep-off constraint, warm start, failure handling and input checks."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

from impact_env.transport.physics import World
from impact_env.transport.scenario import Body, Scenario, scenario_from_dict
from planners.online.mpc import (
    AvoidSpec,
    FreeflyerMPC,
    ImpactSpec,
    MPCConfig,
    MPCInputError,
    rk4_step,
    state_from_sim,
)
from tests.helpers import two_body
from tests.paths import ROOT

DT = 0.1


def solo(position=(2.0, 5.0), heading: float = 0.0, velocity=(0.0, 0.0)) -> Scenario:
    """One robot (the paper's freeflyer) alone in a 10 m box."""
    return scenario_from_dict({
        "name": "solo", "restitution": 0.75, "tf_s": 60.0, "task": "F[0,10] in(R1, goal)",
        "world": {"box": [0.0, 10.0, 0.0, 10.0]}, "regions": [{"name": "goal", "box": [8.0, 9.0, 4.0, 6.0]}],
        "robots": [{"name": "R1", "mass_kg": 16.8, "radius_m": 0.2, "inertia_kgm2": 0.1594,
                    "position_m": list(position), "velocity_mps": list(velocity), "heading_rad": heading,
                    "thrust_limit_N": [2.8, 2.8], "torque_limit_Nm": 0.2}],
    })


@pytest.fixture(scope="module")
def robot() -> Body:
    return solo().robots[0]


@pytest.fixture(scope="module")
def mpc(robot: Body) -> FreeflyerMPC:
    return FreeflyerMPC(robot)


def line_reference(t: np.ndarray, start=(1.0, 0.0), speed: float = 0.2) -> np.ndarray:
    """(len(t), 4) [x, y, vx, vy]: along +x at ``speed`` from ``start``."""
    return np.stack([start[0] + speed * t, start[1] + 0 * t, speed + 0 * t, 0 * t], axis=1)


# ------------------------------------------------------------------------------------------------ model
def test_rk4_constant_body_force_is_exact(robot: Body) -> None:
    theta, force = 0.7, np.array([1.2, -0.8])
    c, s = math.cos(theta), math.sin(theta)
    accel = np.array([c * force[0] - s * force[1], s * force[0] + c * force[1]]) / robot.mass_kg
    x = np.array([1.0, 2.0, theta, 0.1, -0.05, 0.0])
    for _ in range(7):
        x = rk4_step(x, np.array([*force, 0.0]), robot, DT)
    t = 7 * DT
    p0, v0 = np.array([1.0, 2.0]), np.array([0.1, -0.05])
    np.testing.assert_allclose(x[0:2], p0 + v0 * t + 0.5 * accel * t ** 2, atol=1e-12)
    np.testing.assert_allclose(x[3:5], v0 + accel * t, atol=1e-12)
    assert x[2] == pytest.approx(theta, abs=1e-15) and x[5] == 0.0


def test_rk4_pure_torque_grows_yaw_rate_linearly(robot: Body) -> None:
    x = np.array([3.0, 4.0, 0.2, 0.0, 0.0, 0.05])
    for _ in range(12):
        x = rk4_step(x, np.array([0.0, 0.0, 0.15]), robot, DT)
    t, alpha = 12 * DT, 0.15 / robot.inertia_kgm2
    assert x[5] == pytest.approx(0.05 + alpha * t, abs=1e-12)
    assert x[2] == pytest.approx(0.2 + 0.05 * t + 0.5 * alpha * t ** 2, abs=1e-12)
    np.testing.assert_array_equal(x[[0, 1, 3, 4]], [3.0, 4.0, 0.0, 0.0])


def test_rk4_matches_pymunk_over_20_periods() -> None:
    sc = solo(heading=0.3, velocity=(0.05, -0.02))
    world = World(sc)
    x = state_from_sim(world.read_state()[0])
    wrench = (1.0, -0.5, 0.02)  # turning while thrusting: the body-frame force rotates
    for _ in range(20):
        world.step([wrench])
        x = rk4_step(x, np.array(wrench), sc.robots[0], sc.control_period_s)
    sim = state_from_sim(world.read_state()[0])
    # pymunk's symplectic Euler (10 substeps of h = 0.01 s) lags by about |a| h T / 2 = 0.7 mm here
    assert np.hypot(*(sim[0:2] - x[0:2])) < 1e-3
    assert sim[2] == pytest.approx(x[2], abs=2e-3)
    np.testing.assert_allclose(sim[3:6], x[3:6], atol=1e-3)


def test_state_from_sim_puts_heading_third() -> None:
    np.testing.assert_array_equal(state_from_sim((1, 2, 3, 4, 5, 6)), [1, 2, 5, 3, 4, 6])


# ------------------------------------------------------------------------------------------ closed loop
def trapezoid_reference(t: np.ndarray) -> np.ndarray:
    """From (2, 5): 0.2 m/s along +x until t = 15 s, then a stop at 0.1 m/s^2 (within the thrust limits)."""
    v = np.where(t < 15.0, 0.2, np.maximum(0.2 - 0.1 * (t - 15.0), 0.0))
    tc = np.clip(t - 15.0, 0.0, 2.0)
    x = 2.0 + 0.2 * np.minimum(t, 15.0) + 0.2 * tc - 0.05 * tc ** 2
    return np.stack([x, 5.0 + 0 * t, v, 0 * t], axis=1)


def test_closed_loop_tracking_in_pymunk() -> None:
    sc = solo(position=(2.0, 5.1), heading=0.3)  # starts 10 cm off the line, at rest
    mpc = FreeflyerMPC(sc.robots[0], heading_ref=0.3)
    world = World(sc)
    n = mpc.horizon
    errors, headings = [], []
    for i in range(300):
        state = state_from_sim(world.read_state()[0])
        result = mpc.solve(state, trapezoid_reference(DT * (i + np.arange(n + 1))))
        assert result.success, (i, result.status)
        assert np.all(np.isfinite(result.wrench)) and np.all(np.abs(result.wrench) <= mpc.bounds)
        world.step([tuple(result.wrench)])
        state = state_from_sim(world.read_state()[0])
        errors.append(np.hypot(*(state[0:2] - trapezoid_reference(np.array([DT * (i + 1)]))[0, 0:2])))
        headings.append(state[2])
    assert max(errors[50:]) < 0.02  # after convergence (5 s)
    assert errors[-1] < 1e-3
    assert max(abs(h - 0.3) for h in headings) < 0.05
    assert mpc.failures == 0 and mpc.solves == 300


def test_closed_loop_push_with_planned_impact() -> None:
    """The robot accelerates from rest, hits an object at rest at the planned node with the planned velocity,
    and continues from the planned post-impact velocity (Eq. 5: v' = (1 - e) / 2 v for equal masses)."""
    e = 0.75
    sc = two_body(e=e, robot_pos=(1.5, 5.05), robot_vel=(0.0, 0.0), object_pos=(3.0, 5.0))
    world = World(sc)
    mpc = FreeflyerMPC(sc.robots[0])
    t_hit, v_pre = 6.5, 0.2
    v_post = (1 - e) / 2 * v_pre

    def reference(t: np.ndarray) -> np.ndarray:
        ramp = np.minimum(t, 2.0)
        x = np.where(t <= t_hit, 1.5 + 0.05 * ramp ** 2 + v_pre * np.maximum(t - 2.0, 0.0),
                     2.6 + v_post * (t - t_hit))
        v = np.where(t <= t_hit + 1e-9, np.minimum(0.1 * t, v_pre), v_post)
        return np.stack([x, 5.0 + 0 * t, v, 0 * t], axis=1)

    n, hit_node = mpc.horizon, round(t_hit / DT)
    events, errors = [], []
    for i in range(hit_node + 20):
        step = hit_node - i
        impact = ImpactSpec(step, (2.6, 5.0), (v_pre, 0.0), (v_post, 0.0)) if 0 <= step <= n else None
        result = mpc.solve(state_from_sim(world.read_state()[0]), reference(DT * (i + np.arange(n + 1))), impact)
        assert result.success, (i, result.status)
        events += world.step([tuple(result.wrench)])
        state = state_from_sim(world.read_state()[0])
        errors.append(np.hypot(*(state[0:2] - reference(np.array([DT * (i + 1)]))[0, 0:2])))
    hits = [ev for ev in events if {ev.a, ev.b} == {"R1", "O1"}]
    assert len(hits) == 1
    hit = hits[0]
    assert hit.time_s == pytest.approx(t_hit, abs=0.02)
    np.testing.assert_allclose(hit.velocity_before("R1"), (v_pre, 0.0), atol=2e-3)
    np.testing.assert_allclose(hit.velocity_after("O1"), ((1 + e) / 2 * v_pre, 0.0), atol=2e-3)
    assert max(errors[hit_node + 1:]) < 5e-3  # and follows the post-impact reference


# ------------------------------------------------------------------------------------------- impact node
@pytest.fixture(scope="module")
def reachable_impact(robot: Body) -> tuple[np.ndarray, ImpactSpec]:
    """A state and an impact 5 nodes ahead whose pre-impact state a feasible wrench reaches exactly."""
    x0 = np.array([1.0, 0.0, 0.0, 0.2, 0.0, 0.0])
    z = x0.copy()
    for _ in range(5):
        z = rk4_step(z, np.array([1.5, -1.0, 0.0]), robot, DT)
    return x0, ImpactSpec(5, z[0:2], z[3:5], np.array([0.02, 0.01]))


@pytest.mark.parametrize("solver", ["sqp", "fatrop", "ipopt"])
def test_impact_node_is_met_and_prediction_jumps(robot: Body, reachable_impact, solver: str) -> None:
    x0, impact = reachable_impact
    mpc = FreeflyerMPC(robot, MPCConfig(solver=solver, fallback_solver=None))
    result = mpc.solve(x0, line_reference(DT * np.arange(11)), impact=impact)
    assert result.success, result.status
    node = result.predicted[5]
    np.testing.assert_allclose(node[0:2], impact.position, atol=1e-3)
    np.testing.assert_allclose(node[3:5], impact.velocity_before, atol=1e-3)
    assert result.impact_error < 1e-6
    # node 6 is one RK4 step from [p_5, theta_5, velocity_after, omega_5], not from x_5
    after = rk4_step(np.r_[node[0:3], impact.velocity_after, node[5]], result.inputs[5], robot, DT)
    np.testing.assert_allclose(result.predicted[6], after, atol=1e-9)
    assert np.all(np.abs(result.inputs) <= mpc.bounds)


def test_the_zero_copy_call_gives_the_numbers_of_a_plain_solver_call(robot: Body, reachable_impact) -> None:
    """solve() calls the solver through its buffer (inputs bound once, written in place): the same problem
    through the ordinary numpy call must give the same iterate to the last bit."""
    x0, impact = reachable_impact
    mpc = FreeflyerMPC(robot, MPCConfig(fallback_solver=None, keep_off_rows=2))
    ref = line_reference(DT * np.arange(11))
    x1 = rk4_step(x0, mpc.solve(x0, ref).wrench, robot, DT)  # the next solve starts warm
    lam_x, lam_g = mpc._lam_x.copy(), mpc._lam_g.copy()  # overwritten by the solve below
    avoid = AvoidSpec(np.tile([1.6, 0.3], (11, 1)), 0.4, np.ones(11, dtype=bool))
    result = mpc.solve(x1, ref, impact, avoid)
    assert result.success
    inputs = {name: value.copy() for name, value in mpc._in.items()}
    inputs["lam_x0"], inputs["lam_g0"] = lam_x, lam_g
    switched_on = np.isfinite(inputs["lbg"]) & ~np.isfinite(mpc._lbg)
    assert switched_on.sum() == 4 + 10  # the impact node's rows and one keep-off row per node
    plain = mpc._solvers["sqp"](**inputs)
    np.testing.assert_array_equal(result.predicted[1:], plain["x"].full().ravel()[mpc._x_idx])


def test_solvers_agree_on_the_optimum(robot: Body, reachable_impact) -> None:
    x0, impact = reachable_impact
    ref = line_reference(DT * np.arange(11))
    wrenches = [FreeflyerMPC(robot, MPCConfig(solver=s, fallback_solver=None)).solve(x0, ref, impact).wrench
                for s in ("sqp", "fatrop", "ipopt")]
    np.testing.assert_allclose(wrenches[1], wrenches[0], atol=1e-3)
    np.testing.assert_allclose(wrenches[2], wrenches[0], atol=1e-3)


def test_impact_at_step_zero_only_applies_the_jump(mpc: FreeflyerMPC, robot: Body) -> None:
    mpc.reset()
    x0 = np.array([1.0, 0.0, 0.0, 0.2, 0.0, 0.0])
    impact = ImpactSpec(0, (5.0, 5.0), (9.0, 9.0), (0.03, 0.0))  # pre-impact values are not enforced at node 0
    result = mpc.solve(x0, line_reference(DT * np.arange(11), speed=0.03), impact=impact)
    assert result.success
    np.testing.assert_allclose(result.predicted[1], rk4_step(np.r_[x0[0:3], 0.03, 0.0, 0.0], result.inputs[0],
                                                             robot, DT), atol=1e-9)


def test_unreachable_impact_state_stays_feasible(mpc: FreeflyerMPC) -> None:
    mpc.reset()
    x0 = np.array([1.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    impact = ImpactSpec(3, (3.0, 0.0), (1.0, 0.0), (0.0, 0.0))  # 2 m in 0.3 s: impossible
    result = mpc.solve(x0, line_reference(DT * np.arange(11)), impact=impact)
    assert result.success and result.impact_error > 0.5
    assert result.inputs[0, 0] == pytest.approx(mpc.bounds[0])  # full thrust towards it


# --------------------------------------------------------------------------------------------- keep-off
def test_keep_off_in_closed_loop() -> None:
    """The reference runs through a static object (10 cm off its centre); the robot goes around it."""
    sc = solo(position=(1.0, 5.0), velocity=(0.2, 0.0))
    world = World(sc)
    mpc = FreeflyerMPC(sc.robots[0])
    n, center = mpc.horizon, np.array([2.0, 5.1])
    avoid = AvoidSpec(np.tile(center, (n + 1, 1)), 0.4, np.ones(n + 1, dtype=bool))
    distances, clearances = [], []
    for i in range(150):
        state = state_from_sim(world.read_state()[0])
        result = mpc.solve(state, line_reference(DT * (i + np.arange(n + 1)), start=(1.0, 5.0)), avoid=avoid)
        assert result.success, (i, result.status)
        predicted = np.hypot(*(result.predicted[1:, 0:2] - center).T)
        clearances.append(predicted.min())
        world.step([tuple(result.wrench)])
        distances.append(np.hypot(*(np.array(world.read_state()[0][0:2]) - center)))
    assert min(clearances) >= 0.38 and min(distances) >= 0.38
    assert distances[-1] > 1.0  # got past it
    final = state_from_sim(world.read_state()[0])
    assert abs(final[1] - 5.0) < 0.05  # and back on the line


def test_inactive_keep_off_changes_nothing(mpc: FreeflyerMPC) -> None:
    x0 = np.array([1.0, 0.0, 0.0, 0.2, 0.0, 0.0])
    ref = line_reference(DT * np.arange(11))
    mpc.reset()
    free = mpc.solve(x0, ref)
    mpc.reset()
    off = mpc.solve(x0, ref, avoid=AvoidSpec(np.tile([1.5, 0.0], (11, 1)), 0.4, np.zeros(11, dtype=bool)))
    np.testing.assert_allclose(off.wrench, free.wrench, atol=1e-9)
    assert off.min_clearance_m == math.inf


# ----------------------------------------------------------------------------------- warm start, failures
def test_warm_start_saves_iterations_and_reset_forgets_it(robot: Body) -> None:
    """Past a keep-off disc (non-convex), warm-started solves need far fewer SQP iterations than cold ones."""
    mpc, cold_mpc = FreeflyerMPC(robot), FreeflyerMPC(robot)
    avoid = AvoidSpec(np.tile([2.0, 0.1], (11, 1)), 0.4, np.ones(11, dtype=bool))
    x, warm, cold = np.array([1.0, 0.05, 0.0, 0.0, 0.0, 0.0]), 0, 0
    for i in range(40):
        ref = line_reference(DT * (i + np.arange(11)))
        result = mpc.solve(x, ref, avoid=avoid)
        cold_mpc.reset()
        warm += result.iterations
        cold += cold_mpc.solve(x, ref, avoid=avoid).iterations
        x = rk4_step(x, result.wrench, robot, DT)
    assert warm < 0.7 * cold
    ref = line_reference(DT * (40 + np.arange(11)))
    mpc.reset()
    np.testing.assert_array_equal(mpc.solve(x, ref, avoid=avoid).wrench,
                                  FreeflyerMPC(robot).solve(x, ref, avoid=avoid).wrench)


def test_failure_returns_a_clipped_finite_wrench(robot: Body, reachable_impact) -> None:
    x0, impact = reachable_impact
    mpc = FreeflyerMPC(robot, MPCConfig(sqp_max_iter=1, fallback_solver=None))
    result = mpc.solve(x0, line_reference(DT * np.arange(11)), impact=impact)
    assert not result.success and mpc.failures == 1
    assert np.all(np.isfinite(result.wrench)) and np.all(np.abs(result.wrench) <= mpc.bounds)
    assert np.all(np.isfinite(result.predicted))


def test_fallback_solver_rescues_a_failed_solve(robot: Body, reachable_impact) -> None:
    x0, impact = reachable_impact
    mpc = FreeflyerMPC(robot, MPCConfig(sqp_max_iter=1, fallback_solver="ipopt"))
    result = mpc.solve(x0, line_reference(DT * np.arange(11)), impact=impact)
    assert result.success and result.solver == "ipopt"
    assert mpc.fallbacks == 1 and mpc.failures == 0


def test_thrust_fraction_scales_the_bounds(robot: Body) -> None:
    mpc = FreeflyerMPC(robot, MPCConfig(thrust_fraction=0.25))
    result = mpc.solve(np.zeros(6), line_reference(DT * np.arange(11), start=(2.0, 1.0)))
    np.testing.assert_allclose(mpc.bounds, [0.7, 0.7, 0.05])
    assert np.all(np.abs(result.inputs) <= mpc.bounds) and abs(result.wrench[0]) == pytest.approx(0.7)


def test_update_weights_takes_effect_without_rebuild(robot: Body) -> None:
    mpc = FreeflyerMPC(robot)
    x0, ref = np.zeros(6), line_reference(DT * np.arange(11), start=(0.3, 0.0))
    soft = mpc.solve(x0, ref).wrench[0]
    mpc.reset()
    mpc.update_weights(r_input=100.0)
    assert mpc.solve(x0, ref).wrench[0] < 0.5 * soft
    with pytest.raises(ValueError, match="unknown weight"):
        mpc.update_weights(q_position=1.0)


def test_heading_reference_is_unwrapped(robot: Body) -> None:
    mpc = FreeflyerMPC(robot, heading_ref=0.1)
    x0 = np.array([1.0, 0.0, 0.1 + 4 * math.pi, 0.0, 0.0, 0.0])  # the same heading, two turns later
    result = mpc.solve(x0, np.tile([1.0, 0.0, 0.0, 0.0], (11, 1)))
    np.testing.assert_allclose(result.wrench, 0.0, atol=1e-6)


# -------------------------------------------------------------------------------------------- bad inputs
@pytest.mark.parametrize("state,reference,match", [
    (np.zeros(5), np.zeros((11, 4)), r"state must have shape \(6,\)"),
    (np.array([0, 0, np.nan, 0, 0, 0]), np.zeros((11, 4)), "state contains NaN"),
    (np.zeros(6), np.zeros((10, 4)), r"reference must have shape \(11, 4\)"),
    (np.zeros(6), np.full((11, 4), np.inf), "reference contains NaN or infinite"),
    ("abc", np.zeros((11, 4)), "state must be numbers"),
])
def test_bad_state_or_reference(mpc: FreeflyerMPC, state, reference, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        mpc.solve(state, reference)


def test_bad_impact_and_avoid_specs(mpc: FreeflyerMPC) -> None:
    x0, ref = np.zeros(6), np.zeros((11, 4))
    with pytest.raises(ValueError, match=r"step must be in 0..10"):
        mpc.solve(x0, ref, impact=ImpactSpec(11, (0, 0), (0, 0), (0, 0)))
    with pytest.raises(ValueError, match="ImpactSpec.velocity_after must have shape"):
        ImpactSpec(3, (0, 0), (0, 0), (0, 0, 0))
    with pytest.raises(ValueError, match="ImpactSpec.step must be an integer"):
        ImpactSpec(2.5, (0, 0), (0, 0), (0, 0))
    with pytest.raises(ValueError, match="min_distance must be a finite number > 0"):
        AvoidSpec(np.zeros((11, 2)), -0.4, np.ones(11, dtype=bool))
    with pytest.raises(ValueError, match=r"AvoidSpec.centers must have shape \(11, 2\)"):
        mpc.solve(x0, ref, avoid=AvoidSpec(np.zeros((10, 2)), 0.4, np.ones(11, dtype=bool)))
    with pytest.raises(ValueError, match=r"AvoidSpec.active must have shape \(11,\)"):
        mpc.solve(x0, ref, avoid=AvoidSpec(np.zeros((11, 2)), 0.4, np.ones(3, dtype=bool)))
    with pytest.raises(MPCInputError, match="impact must be an ImpactSpec"):
        mpc.solve(x0, ref, impact=(3, (0, 0)))


@pytest.mark.parametrize("kwargs,match", [
    ({"horizon": 1}, "horizon must be an integer >= 2"),
    ({"dt_s": 0.0}, "dt_s must be a finite number > 0"),
    ({"q_pos": -1.0}, "q_pos must be a finite number >= 0"),
    ({"thrust_fraction": 1.5}, r"MPCConfig.thrust_fraction must be a finite number in \(0, 1\]"),
    ({"solver": "highs"}, "solver must be one of sqp, fatrop, ipopt"),
])
def test_bad_config(kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        MPCConfig(**kwargs)


def test_an_object_is_not_a_robot() -> None:
    obj = two_body().objects[0]
    with pytest.raises(ValueError, match="not a robot"):
        FreeflyerMPC(obj)


def test_runs_next_to_highspy() -> None:
    """The planner's highspy and CasADi share a process: the MPC must not load CasADi's own libhighs."""
    code = ("import highspy, numpy as np; from tests.planners.online.test_mpc import solo; "
            "from planners.online.mpc import FreeflyerMPC; "
            "r = FreeflyerMPC(solo().robots[0]).solve(np.zeros(6), np.zeros((11, 4))); assert r.success")
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120, cwd=ROOT)
