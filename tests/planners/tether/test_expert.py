"""The tether expert in the tether environments, and the ``plan`` / ``run`` commands for stations."""

from __future__ import annotations

import json

import numpy as np
import pytest

from impact_env.cli import main
from impact_env.controllers import make_controller
from impact_env.rollout import run_episode
from impact_env.tether.gym_env import TetherEnv
from impact_env.tether.pettingzoo_env import TetherParallelEnv
from impact_env.tether.station import load_station, station_names
from planners.errors import PlannerError
from planners.tether.expert import TetherExpert
from planners.tether.plan import TetherPlan
from planners.tether.reachability import plan_reachability
from tests.station_helpers import station_dict


def _fly(name, fidelity="kinematic", seed=0, w_factor=1.0, noise=0.0, expert=None):
    st = load_station(name)
    env = TetherEnv(st, fidelity=fidelity, pull_speed_mps=st.pull_speed_mps * w_factor,
                    initial_position_noise_m=noise)
    expert = expert or TetherExpert(st)
    res = run_episode(env, expert, seed=seed)
    env.close()
    return res, expert


@pytest.mark.parametrize("name", station_names())
def test_expert_delivers_on_every_shipped_map_under_kinematic(name):
    res, expert = _fly(name)
    assert res.success and res.robustness > 0.05, res.final_info
    info = res.final_info
    st = load_station(name)
    fewest = plan_reachability(st).switches
    # no snag, and no dithering between anchors: at most one extra attachment per planned pull
    assert info["snags"] == 0 and fewest <= info["switches"] <= 2 * fewest
    # the disc stayed inside the station all the way (a contact overlaps by less than a substep's motion)
    assert all(st.cargo_inside(p[0], tol_m=0.01) for p in res.positions)


@pytest.mark.parametrize("name,seed,w_factor", [("L", 0, 0.9), ("L", 1, 1.1), ("dead_end", 2, 0.9),
                                                ("iss_chain", 3, 1.1)])
def test_expert_delivers_under_reel_with_wrong_w_and_a_perturbed_start(name, seed, w_factor):
    res, expert = _fly(name, "reel", seed=seed, w_factor=w_factor, noise=0.3)
    assert res.success, (res.final_info, expert.report())
    assert expert.stats.brakes >= 1  # under inertia every change of anchor is braked


@pytest.mark.parametrize("name", ["L", "alcove"])
def test_expert_delivers_under_force(name):
    res, _ = _fly(name, "force", seed=4, noise=0.3)
    assert res.success, res.final_info


@pytest.mark.slow
@pytest.mark.parametrize("name", station_names())
@pytest.mark.parametrize("w_factor", [0.9, 1.1])
def test_expert_succeeds_in_95_percent_of_50_perturbed_reel_episodes(name, w_factor):
    st = load_station(name)
    env = TetherEnv(st, fidelity="reel", pull_speed_mps=st.pull_speed_mps * w_factor, initial_position_noise_m=0.3)
    expert = TetherExpert(st)
    wins = sum(run_episode(env, expert, seed=seed).success for seed in range(50))
    assert wins >= 48, f"{wins}/50"


def test_expert_replans_from_a_perturbed_start():
    res, expert = _fly("T", seed=5, noise=0.3)
    assert res.success
    start = res.positions[0][0]
    assert np.hypot(*(start - np.array(load_station("T").cargo.start_m))) > 0.0
    assert expert.stats.replans >= 1


def test_per_agent_form_drives_the_pettingzoo_env():
    st = load_station("L")
    env = TetherParallelEnv(st)
    expert = TetherExpert(st)
    obs, infos = env.reset(seed=0)
    expert.reset(env)
    done = False
    while not done:
        actions = {a: expert.agent_action(a, obs[a]) for a in env.agents}
        obs, rewards, terms, truncs, infos = env.step(actions)
        done = not env.agents
    last = next(iter(infos.values()))
    assert last["is_success"], last


def test_expert_rejects_a_plan_for_another_station_and_a_bad_observation():
    plan = plan_reachability(load_station("L"))
    with pytest.raises(PlannerError, match="for station 'L'"):
        TetherExpert(load_station("T"), plan=plan)
    expert = TetherExpert(load_station("L"))
    with pytest.raises(ValueError, match="observation must have shape"):
        expert.act(np.zeros(3))


def test_expert_controller_from_the_entry_point_takes_a_saved_plan(tmp_path):
    st = load_station("dead_end")
    path = plan_reachability(st).save(tmp_path / "plan.json")
    controller = make_controller("expert", st, plan=str(path))
    assert isinstance(controller, TetherExpert)
    assert controller.initial_plan.pulls == TetherPlan.load(path).pulls


# ------------------------------------------------------------------------------------------------ CLI
def test_plan_command_writes_a_checked_plan_and_a_figure(tmp_path, capsys):
    out, png = tmp_path / "L.json", tmp_path / "L.png"
    assert main(["plan", "L", "--out", str(out), "--plot", str(png)]) == 0
    text = capsys.readouterr().out
    assert "3 pulls" in text and "travel time" in text and "(k = 3)" in text
    plan = TetherPlan.load(out)
    plan.check(load_station("L"))
    assert png.stat().st_size > 10_000
    assert main(["run", "L", "--controller", "expert", "--plan", str(out), "--json", str(tmp_path / "r.json")]) == 0
    summary = json.loads((tmp_path / "r.json").read_text())
    assert summary["success"] and summary["controller"] == "expert"
    # the winches 10 % slower than the station says, and a perturbed start
    assert main(["run", "L", "--controller", "expert", "--fidelity", "reel", "--pull-speed-mps", "0.09",
                 "--initial-position-noise-m", "0.3", "--seed", "7", "--json", str(tmp_path / "w.json")]) == 0
    summary = json.loads((tmp_path / "w.json").read_text())
    assert summary["success"] and summary["env_options"]["pull_speed_mps"] == 0.09
    assert main(["run", "corridor", "--pull-speed-mps", "0.1"]) == 2  # a station-only option


def test_plan_command_proves_infeasibility_with_exit_code_4(tmp_path, capsys):
    d = station_dict(anchors={"spacing_m": 2.5, "walls": [0]})
    lines = [f'name = "{d["name"]}"', f"restitution = {d['restitution']}", f"tf_s = {d['tf_s']}", "[station]",
             f"polygon = {d['station']['polygon']}", "[anchors]", "spacing_m = 2.5", "walls = [0]", "[cargo]",
             "mass_kg = 20.0", "radius_m = 0.3", "start_m = [2.5, 1.5]", "[goal]", "center_m = [18.5, 12.5]",
             "half_size_m = 0.5", "[robots]", "count = 3", "max_active = 2", "pull_speed_mps = 0.1",
             "winch_force_limit_N = 1.0", "stop_radius_m = 0.6", "switch_time_s = 5.0"]
    path = tmp_path / "bottom_only.toml"
    path.write_text("\n".join(lines) + "\n")
    assert main(["plan", str(path)]) == 4
    assert "infeasible (proved)" in capsys.readouterr().out


def test_plan_command_thesis_pipeline_and_drh(tmp_path, capsys):
    pytest.importorskip("z3")
    drh = tmp_path / "L.drh"
    assert main(["plan", "L", "--method", "smt", "--drh", str(drh), "--quiet"]) == 0
    assert "pulls" in capsys.readouterr().out and drh.read_text().startswith("[")
    assert main(["plan", "dead_end", "--method", "smt", "--rule", "region", "--quiet"]) == 5
    assert "found no plan" in capsys.readouterr().out
