"""The expert (plan + replanner + MPC) closed loop in the Gymnasium env, its wrapper and CLI."""

from __future__ import annotations

import json

import numpy as np
import pytest

import impact_env
from impact_env.cli import main
from impact_env.transport.gym_env import TransportEnv
from impact_env.transport.scenario import load_scenario
from planners.expert import Expert
from planners.expert.wrappers import ExpertActionInfo
from tests.shipped_plans import path as committed_plan


@pytest.fixture(scope="module")
def experts(shipped_plans):
    """The expert on the committed plans of two shipped scenarios (tests/conftest.py)."""
    names = ("throw_and_catch_exp", "corridor")
    return {name: Expert(load_scenario(name), plan=shipped_plans.sr(name)) for name in names}


def fly(expert: Expert, seed: int = 0, **env_options) -> tuple[dict, np.ndarray, TransportEnv]:
    env = TransportEnv(expert.scenario, **env_options)
    obs, info = env.reset(seed=seed)
    expert.reset()
    done = False
    while not done:
        obs, _, terminated, truncated, info = env.step(expert.act(obs, info))
        done = terminated or truncated
    return info, obs, env


@pytest.mark.parametrize("name", ["throw_and_catch_exp", "corridor"])
def test_closed_loop_satisfies_the_task_and_the_object_ends_in_the_goal(experts, name):
    expert = experts[name]
    info, obs, env = fly(expert)
    assert info["is_success"], f"robustness {info['robustness']}"
    o1 = env.core.body_names.index("O1")
    final = obs[7 * o1: 7 * o1 + 2]
    assert expert.scenario.region_map()["goal"].signed_distance_xy(*final) > 0
    assert expert.stats.mpc_failures == 0
    assert expert.stats.replans > 0


def test_closed_loop_under_model_mismatch(experts):
    """Restitution off by 0.1, the object 5 cm off, 5 % thrust noise: still succeeds."""
    expert = experts["throw_and_catch_exp"]
    e = expert.scenario.restitution
    for seed, restitution in ((1, e + 0.1), (2, e - 0.1)):
        info, _, _ = fly(expert, seed=seed, restitution=restitution, initial_position_noise_m=0.05,
                         thrust_noise=0.05)
        assert info["is_success"], f"seed {seed}, e {restitution}: robustness {info['robustness']}"


def test_expert_action_wrapper_labels_every_step(experts):
    expert = experts["throw_and_catch_exp"]
    env = ExpertActionInfo(TransportEnv(expert.scenario), expert)
    obs, info = env.reset(seed=0)
    assert info["expert_action"].shape == env.action_space.shape
    for _ in range(20):  # the learner does nothing; the expert still labels
        obs, _, _, _, info = env.step(np.zeros(env.action_space.shape))
        assert env.action_space.contains(info["expert_action"])


def test_pettingzoo_agent_actions_match_the_central_action(experts):
    expert = experts["throw_and_catch_exp"]
    par = impact_env.parallel_env(scenario="throw_and_catch_exp")
    observations, _ = par.reset(seed=0)
    expert.reset()
    for _ in range(30):
        actions = {a: expert.agent_action(a, observations[a]) for a in par.agents}
        central = expert.act(par.state())
        np.testing.assert_allclose(np.concatenate([actions["R1"], actions["R2"]]), central)
        observations, *_ = par.step(actions)


def test_plan_for_another_scenario_is_rejected(experts):
    from planners.errors import PlannerError

    with pytest.raises(PlannerError, match="plan is for scenario"):
        Expert(load_scenario("corridor"), plan=experts["throw_and_catch_exp"].plan)


def test_cli_run_with_the_expert_and_a_saved_plan(tmp_path):
    plan_path = committed_plan("sr", "throw_and_catch_exp")  # a saved plan: the committed one
    out, fig = tmp_path / "run.json", tmp_path / "run.png"
    code = main(["run", "throw_and_catch_exp", "--controller", "expert", "--plan", str(plan_path),
                 "--json", str(out), "--plot", str(fig)])
    assert code == 0
    summary = json.loads(out.read_text())
    assert summary["success"] is True
    assert {"median", "p99"} <= set(summary["controller_ms"])
    report = summary["controller_report"]
    assert report["planned_robustness"] == pytest.approx(0.4, abs=1e-3) and report["replans"] > 0
    assert fig.stat().st_size > 1000


@pytest.mark.slow
def test_closed_loop_obstacle_avoidance(shipped_plans):
    expert = Expert(load_scenario("obstacle_avoidance"), plan=shipped_plans.sr("obstacle_avoidance"))
    info, obs, env = fly(expert)
    assert info["is_success"], f"robustness {info['robustness']}"
    o1 = env.core.body_names.index("O1")
    assert expert.scenario.region_map()["goal"].signed_distance_xy(*obs[7 * o1: 7 * o1 + 2]) > 0
