"""The tether ids of version 1 and the version 0 kept for one release, the PettingZoo agents named by the
station's robots, the expert flying the plan it is given, and the planner's exit codes."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest

import impact_env
from impact_env import TETHER_GYM_IDS, TETHER_GYM_IDS_V0
from impact_env.cli import main
from impact_env.rollout import run_episode
from impact_env.tether.gym_env import TetherEnv, TetherEnvV0
from impact_env.tether.station import load_station, station_from_dict
from planners.errors import PlannerError, TetherPlanCheckError
from planners.tether.expert import TetherExpert
from planners.tether.plan import Pull, TetherPlan
from planners.tether.reachability import ReachabilityPlanner
from tests.station_helpers import station_dict


def test_v1_ids_fly_the_hold_task_and_v0_ids_keep_the_old_one():
    assert set(TETHER_GYM_IDS) == {f"impact_env/Tether{n}-v1" for n in ("L", "T", "Alcove", "IssChain", "DeadEnd")}
    for v1, v0 in zip(TETHER_GYM_IDS, TETHER_GYM_IDS_V0):
        new, old = gym.make(v1), gym.make(v0)
        st = new.unwrapped.station
        assert new.unwrapped.core.task == st.hold_task and old.unwrapped.core.task == st.reach_task
        assert new.action_space.nvec.tolist() == [st.n_anchors + 3] * st.n_robots
        assert old.action_space.nvec.tolist() == [st.n_anchors + 2] * st.n_robots
        assert type(new.unwrapped) is TetherEnv and type(old.unwrapped) is TetherEnvV0
        assert new.spec.max_episode_steps == old.spec.max_episode_steps == 600
    assert gym.spec("impact_env/Tether-v1").max_episode_steps is None


def test_pettingzoo_agents_are_the_station_robots_names():
    env = impact_env.tether_v1.parallel_env(station="L")
    assert env.possible_agents == ["R1", "R2", "R3"] and env.metadata["name"] == "tether_L_v1"
    assert impact_env.tether_v0.parallel_env(station="L").possible_agents == ["robot_0", "robot_1", "robot_2"]
    data = station_dict()
    data["robots"]["names"] = ["winch_a", "winch_b", "winch_c"]
    named = impact_env.tether_v1.parallel_env(station=station_from_dict(data))
    assert named.possible_agents == ["winch_a", "winch_b", "winch_c"]
    import pettingzoo

    assert pettingzoo.make("parallel", "impact_env/tether-v1", station="T").possible_agents == ["R1", "R2", "R3"]


def test_the_per_agent_expert_drives_the_v1_pettingzoo_env():
    env = impact_env.tether_v1.parallel_env(station="alcove")
    expert = TetherExpert(env.station)
    observations, _ = env.reset(seed=0)
    expert.reset(env)
    infos = {}
    while env.agents:
        observations, _, _, _, infos = env.step({a: expert.agent_action(a, observations[a]) for a in env.agents})
    info = next(iter(infos.values()))
    assert info["is_success"] and info["time_at_rest_in_goal_s"] >= 30.0


def _smt_like_plan(station) -> TetherPlan:
    """A valid plan that is not the exact planner's: its first pull stops halfway, a second one carries on."""
    plan = ReachabilityPlanner(station).plan()
    first = plan.pulls[0]
    mid = tuple(0.5 * (np.asarray(first.start_m) + np.asarray(first.end_m)))
    pulls = [Pull(first.anchor, first.start_m, mid), Pull(first.anchor, mid, first.end_m), *plan.pulls[1:]]
    return TetherPlan(station.name, plan.start_m, plan.goal_box, pulls, plan.pull_speed_mps, plan.switch_time_s,
                      method="hand-made", hold=plan.hold)


def test_the_expert_flies_the_plan_it_is_given():
    station = load_station("L")
    plan = _smt_like_plan(station)
    plan.check(station)
    env = TetherEnv(station)
    expert = TetherExpert(station, plan=plan)
    res = run_episode(env, expert, seed=0)
    attached = [e["anchor"] for e in env.core.events if e["kind"] == "attached"]
    assert res.success and expert.report()["planned_switches"] == 4  # its four pulls, not the planner's three
    assert attached[:3] == [plan.pulls[0].anchor, plan.pulls[0].anchor, plan.pulls[2].anchor]


def test_a_plan_that_fails_its_check_or_is_for_another_station_is_refused(tmp_path, capsys):
    station = load_station("L")
    plan = ReachabilityPlanner(station).plan()
    bad = TetherPlan.from_dict(plan.to_dict())
    bad.pulls[0] = Pull(bad.pulls[0].anchor, bad.pulls[0].start_m, (4.0, 14.0))
    with pytest.raises(TetherPlanCheckError, match="does not move straight toward anchor"):
        TetherExpert(station, plan=bad)
    with pytest.raises(PlannerError, match="for station 'L', not 'T'"):
        TetherExpert(load_station("T"), plan=plan)
    path = bad.save(tmp_path / "bad.json")
    assert main(["run", "L", "--controller", "expert", "--plan", str(path)]) == 2
    assert "plan check failed" in capsys.readouterr().err
    good = plan.save(tmp_path / "good.json")
    assert main(["run", "T", "--controller", "expert", "--plan", str(good)]) == 2
    assert main(["run", "L", "--controller", "expert", "--plan", str(good), "--json", str(tmp_path / "r.json")]) == 0
    assert json.loads((tmp_path / "r.json").read_text())["success"]


def test_the_planner_exit_codes_and_what_a_failed_pipeline_says(tmp_path, capsys):
    pytest.importorskip("z3")
    assert main(["plan", "dead_end", "--method", "smt", "--rule", "region", "--quiet"]) == 5  # not a proof
    out = capsys.readouterr().out
    assert "region rule" in out and "path [" in out and "stops at region" in out
    assert "1 pull unsat" in out and "z3 verdicts: 0 sat, 3 unsat, 0 unknown" in out and "Not a proof" in out
    assert main(["plan", "no_such_station"]) == 2  # bad input
    assert "impact-env: error: unknown scenario" in capsys.readouterr().err


def test_an_smt_timeout_is_reported_as_unknown_with_its_limit():
    pytest.importorskip("z3")
    from planners.tether.smt import SmtConfig, SmtStats, no_plan_message

    stats = SmtStats(sat=1, unsat=2, unknown=1,
                     failures=[{"path": [0, 2], "region": 2, "why": "no pulls", "verdicts": ["unsat", "unknown"]}])
    text = no_plan_message(load_station("T"), SmtConfig(timeout_s=20.0), [[0, 2]], stats)
    assert "path [0, 2] stops at region 2 (1 pull unsat, 2 pulls unknown)" in text
    assert "unknown means z3 reached its 20 s limit" in text
