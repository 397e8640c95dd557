"""The old module paths of 0.2 after the move to one folder per world family (``impact_env/transport/``,
``impact_env/tether/``): each imports as the very module at its new path with a DeprecationWarning, and files
written by 0.2 that name the old paths still load.

``tests/data/pickles_0.2.0.pkl`` and ``tests/data/env_specs_0.2.0.json`` were written by commit 9eb08e7 (0.2.0,
before the move) with::

    pickle.dumps({"classes": (Scenario, Station, TransportEnv, TetherEnv, TransportParallelEnv, TetherParallelEnv,
                              ImpactEvent, TetherEvent),
                  "scenario": load_scenario("corridor"), "station": load_station("L"),
                  "transport_env": TransportEnv("corridor", reward_mode="sparse"),
                  "tether_env": TetherEnv("L", fidelity="reel"),
                  "transport_parallel_env": TransportParallelEnv("two_objects"),
                  "tether_parallel_env": TetherParallelEnv("T"),
                  "impact_event": ImpactEvent(1.5, "R1", "O1", 0.2, (0.1, 0.0), (0.0, 0.0), (0.0, 0.0), (0.1, 0.0)),
                  "tether_event": TetherEvent(3.0, "attached", 0, 2)}, protocol=4)
    {env_id: gym.spec(env_id).to_json() for env_id in ("impact_env/Corridor-v0", "impact_env/Transport-v0",
                                                      "impact_env/TetherL-v0", "impact_env/Tether-v0")}

so they record ``impact_env.scenario.Scenario``, ``impact_env.envs.transport:TransportEnv`` and the like (the
class paths a user's pickles, SB3 model folders and Minari datasets hold).
"""

from __future__ import annotations

import dataclasses
import importlib
import json
import pickle
import re
import sys

import gymnasium as gym
import numpy as np
import pytest

import impact_env
from impact_env import moved_modules
from impact_env.tether.gym_env import TetherEnv
from impact_env.tether.pettingzoo_env import TetherParallelEnv
from impact_env.tether.physics import TetherEvent
from impact_env.tether.station import Station, load_station
from impact_env.transport.gym_env import TransportEnv
from impact_env.transport.pettingzoo_env import TransportParallelEnv
from impact_env.transport.physics import ImpactEvent
from impact_env.transport.scenario import Scenario, load_scenario
from tests.paths import DATA, ROOT


def changelog_moves() -> dict[str, str]:
    """The table of moves in the CHANGELOG's "Unreleased" section: ``| `old.path` | `new.path` |`` rows."""
    text = (ROOT / "CHANGELOG.md").read_text()
    unreleased = text[text.index("## Unreleased"):text.index("\n## ", text.index("## Unreleased") + 1)]
    path = r"`((?:impact_env|planners)[\w.]*)`"
    return dict(re.findall(rf"^\| {path} \| {path}", unreleased, flags=re.M))


OLD_PATHS = changelog_moves()

# names that 0.2 code imported from the old paths (planners, baselines, benchmarks, tests, the docs), private
# ones among them: each must still be there
OLD_NAMES = {
    "impact_env.scenario": ["Body", "Region", "Scenario", "FinalBox", "load_scenario", "scenario_from_dict",
                            "scenario_names", "MAX_PLANNER_INTERVALS", "MAX_ROBOT_DEGREE", "MIN_ROBOT_DEGREE",
                            "_Fields", "_check", "_short", "_finite", "_positive", "_read_source"],
    "impact_env.station": ["CARGO", "GOAL", "Station", "load_station", "station_from_dict", "station_names",
                           "is_station_file"],
    "impact_env.names": ["suggestion", "shipped_names"],
    "impact_env.plotting": ["DPI", "IMPACT_COLOUR", "OBJECT_TRACE_COLOURS", "ROBOT_TRACE_COLOURS", "draw_scenario",
                            "impacts_text", "trace_colours", "save_scenario_figure", "plot_run", "count_impacts"],
    "impact_env.tether_plotting": ["DPI", "_draw", "_png_path", "draw_station", "save_station_figure",
                                   "plot_tether_run"],
    "impact_env.rendering": ["FORCE_SCALE_M_PER_N", "HEADER_PX", "MARGIN_PX", "Renderer", "RenderFrame",
                             "prepare_display", "ROBOT", "OBJECT", "BACKGROUND", "OBSTACLE"],
    "impact_env.tether_rendering": ["TetherRenderer", "TetherFrame", "frame_of", "RENDER_MODES"],
    "impact_env.envs.render_support": ["impact_flashes", "make_frame", "render", "close", "FLASH_S"],
    "impact_env.envs.core": ["ACTION_PER_ROBOT", "OBS_PER_BODY", "REWARD_MODES", "TransportCore", "EnvConfigError"],
    "impact_env.envs.tether_core": ["ATTACH0", "KEEP", "RELEASE", "TetherCore"],
    "impact_env.envs.tether": ["TetherEnv", "STATION_HINT", "render_tether", "close_tether"],
    "impact_env.envs.transport": ["TransportEnv", "SCENARIO_HINT"],
    "impact_env.envs.clock": ["EpisodeClock", "required", "check_render_options", "check_max_cycles",
                              "reject_unknown"],
    "impact_env.envs.docstrings": ["arguments", "documented_arguments", "sections"],
    "impact_env.tether_physics": ["FIDELITIES", "TetherWorld", "TetherEvent"],
    "impact_env.tether_cli": ["show_station", "run_station"],
}


def import_afresh(name: str):
    """Import ``name`` as a first import would (dropping a cached entry), recording the warnings."""
    sys.modules.pop(name, None)
    with pytest.warns(DeprecationWarning) as record:
        __import__(name)  # as an import statement does (importlib.import_module would be the warning's caller)
    return sys.modules[name], record


def test_every_old_path_is_registered_and_listed_in_the_changelog():
    import planners  # noqa: F401  (registers its own old paths on import; other tests may not have imported it)

    assert len(OLD_PATHS) == 30  # the table was found, both packages' rows
    assert "impact_env.envs.transport" in OLD_PATHS and "planners.funnels" in OLD_PATHS
    assert moved_modules.moves() == OLD_PATHS


@pytest.mark.parametrize("old", sorted(OLD_PATHS))
def test_old_path_imports_the_new_module_with_a_deprecation_warning(old):
    module, record = import_afresh(old)
    new = importlib.import_module(OLD_PATHS[old])
    assert module is new and sys.modules[old] is new
    messages = [str(w.message) for w in record if w.category is DeprecationWarning]
    assert f"{old} has moved to {OLD_PATHS[old]}; the old path will be removed in 0.4.0" in messages
    # the warning points at the importing line (here), not into importlib
    assert any(w.filename == __file__ for w in record)


@pytest.mark.parametrize("old", sorted(OLD_NAMES))
def test_old_paths_keep_the_names_code_imported_from_them(old):
    module, _ = import_afresh(old)
    missing = [name for name in OLD_NAMES[old] if not hasattr(module, name)]
    assert not missing


def test_from_import_of_an_old_path_gives_the_same_objects():
    sys.modules.pop("impact_env.scenario", None)
    with pytest.warns(DeprecationWarning, match="impact_env.scenario has moved"):
        from impact_env.scenario import Scenario as OldScenario
        from impact_env.scenario import _check, _Fields
    from impact_env.toml_fields import Fields, check

    assert OldScenario is Scenario and _check is check and _Fields is Fields


def test_shipped_files_are_found_through_the_old_resource_packages():
    from importlib.resources import files

    import_afresh("impact_env.scenarios")
    import_afresh("impact_env.stations")
    assert files("impact_env.scenarios").joinpath("corridor.toml").read_text() == \
        files("impact_env.transport.scenarios").joinpath("corridor.toml").read_text()
    assert sorted(p.name for p in files("impact_env.stations").iterdir() if p.name.endswith(".toml")) == \
        [f"{name}.toml" for name in impact_env.station_names()]


# ---------------------------------------------------------------------------------- files written by 0.2


@pytest.fixture(scope="module")
def old_pickles() -> dict:
    raw = (DATA / "pickles_0.2.0.pkl").read_bytes()
    for old in (b"impact_env.scenario", b"impact_env.envs.transport", b"impact_env.tether_physics"):
        assert old in raw  # the file names the old paths
    return pickle.loads(raw)


def test_a_pickle_with_the_old_class_paths_loads_as_the_new_classes(old_pickles):
    assert old_pickles["classes"] == (Scenario, Station, TransportEnv, TetherEnv, TransportParallelEnv,
                                      TetherParallelEnv, ImpactEvent, TetherEvent)
    assert old_pickles["scenario"] == load_scenario("corridor")
    assert old_pickles["scenario"].formula.horizon_s == load_scenario("corridor").formula.horizon_s
    fresh = load_station("L")  # 0.2's station had no hold: it keeps the task it was saved with
    assert old_pickles["station"] == dataclasses.replace(fresh, task=fresh.reach_task, hold_s=0.0)
    assert old_pickles["impact_event"].velocity_after("O1") == (0.1, 0.0)
    assert old_pickles["tether_event"].to_dict() == {"time": 3.0, "kind": "attached", "robot": 0, "anchor": 2}


@pytest.mark.parametrize("key,fresh", [
    ("transport_env", lambda: TransportEnv("corridor", reward_mode="sparse")),
    ("tether_env", lambda: TetherEnv("L", fidelity="reel")),
])
def test_gym_envs_pickled_by_0_2_fly_as_new_ones(old_pickles, key, fresh):
    old, new = old_pickles[key], fresh()
    assert type(old) is type(new)
    (obs_old, _), (obs_new, _) = old.reset(seed=4), new.reset(seed=4)
    old.action_space.seed(4)
    new.action_space.seed(4)
    for _ in range(30):
        obs_old, r_old, *_ = old.step(old.action_space.sample())
        obs_new, r_new, *_ = new.step(new.action_space.sample())
    assert np.array_equal(obs_old, obs_new) and r_old == r_new


@pytest.mark.parametrize("key,agents", [("transport_parallel_env", ["R1", "R2"]),
                                        ("tether_parallel_env", ["R1", "R2", "R3"])])  # restored as v1
def test_pettingzoo_envs_pickled_by_0_2_load(old_pickles, key, agents):
    env = old_pickles[key]
    observations, _ = env.reset(seed=0)
    assert sorted(observations) == sorted(agents) and env.possible_agents == agents


@pytest.mark.parametrize("env_id", ["impact_env/Corridor-v0", "impact_env/Transport-v0", "impact_env/TetherL-v0",
                                    "impact_env/Tether-v0"])
def test_env_specs_recorded_by_0_2_still_make_their_env(env_id):
    """Minari stores a dataset's env as its spec's JSON (entry point ``impact_env.envs.transport:TransportEnv``)
    and recovers it with ``gym.make(EnvSpec.from_json(...))``."""
    text = json.loads((DATA / "env_specs_0.2.0.json").read_text())[env_id]
    spec = gym.envs.registration.EnvSpec.from_json(text)
    assert spec.entry_point.startswith(("impact_env.envs.transport:", "impact_env.envs.tether:"))
    kwargs = {} if spec.kwargs else ({"scenario": "corridor"} if "Transport" in env_id else {"station": "L"})
    env = gym.make(spec, **kwargs)
    assert isinstance(env.unwrapped, (TransportEnv, TetherEnv))
    assert env.spec.max_episode_steps == spec.max_episode_steps
    env.reset(seed=0)
    env.close()


def test_the_shipped_ppo_model_still_flies_as_it_did_in_0_2():
    pytest.importorskip("stable_baselines3")
    from impact_env.controllers import make_controller
    from impact_env.rollout import run_episode

    scenario = load_scenario("corridor")
    controller = make_controller(str(ROOT / "tests" / "data" / "models" / "ppo_corridor" / "model.zip"),
                                 scenario)
    result = run_episode(TransportEnv(scenario, thrust_noise=0.05, initial_position_noise_m=0.05), controller, seed=0)
    assert result.steps == 1000
    assert result.robustness == 0.19807305311150453  # measured with 0.2.0 (commit 9eb08e7)
