"""Ecosystem conventions of every environment: registered episode length, the clock on the env, keyword names
that match the CLI, documented arguments, PettingZoo's versioned modules and explicit entry points."""

from __future__ import annotations

import inspect
import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest

import impact_env
from impact_env import GYM_IDS, TETHER_GYM_IDS
from impact_env.env_docstrings import arguments, documented_arguments, sections
from impact_env.envs import TetherEnv, TetherParallelEnv, TransportEnv, TransportParallelEnv

ENV_CLASSES = (TransportEnv, TransportParallelEnv, TetherEnv, TetherParallelEnv)


@pytest.mark.parametrize("env_id", [*GYM_IDS, *TETHER_GYM_IDS])
def test_registered_ids_carry_the_horizon_as_max_episode_steps(env_id):
    env = gym.make(env_id)
    core = env.unwrapped
    assert env.spec.max_episode_steps == core.horizon_steps > 0
    assert core.horizon_s == pytest.approx(core.horizon_steps * core.dt_s)
    source = getattr(core, "scenario", None) or core.station
    assert core.dt_s == source.control_period_s
    env.close()


def test_terminated_at_the_horizon_and_truncated_by_the_time_limit():
    env = gym.make("impact_env/ThrowAndCatchExp-v0")
    env.reset(seed=0)
    zero = np.zeros(env.action_space.shape, dtype=np.float32)
    flags = [env.step(zero)[2:4] for _ in range(env.unwrapped.horizon_steps)]
    assert all(f == (False, False) for f in flags[:-1])
    assert flags[-1] == (True, True)  # the task's end; TimeLimit of the same length marks it too
    short = gym.make("impact_env/ThrowAndCatchExp-v0", max_episode_steps=50)
    short.reset(seed=0)
    flags = [short.step(zero)[2:4] for _ in range(50)]
    assert flags[-1] == (False, True) and all(f == (False, False) for f in flags[:-1])


def test_generic_ids_register_no_length_and_need_their_scenario():
    assert gym.spec("impact_env/Transport-v0").max_episode_steps is None
    assert gym.spec("impact_env/Tether-v0").max_episode_steps is None
    env = gym.make("impact_env/Transport-v0", scenario="corridor")
    assert env.unwrapped.horizon_steps == 1000 and env.unwrapped.dt_s == pytest.approx(0.1)


def test_make_imports_the_package_itself():
    code = ("import gymnasium as gym\n"
            "env = gym.make('impact_env:impact_env/Corridor-v0', reward_mode='sparse')\n"
            "print(env.spec.max_episode_steps, env.unwrapped.core.reward_mode)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["1000", "sparse"]


@pytest.mark.parametrize("cls", ENV_CLASSES, ids=lambda c: c.__name__)
def test_docstring_documents_exactly_the_constructor_keywords(cls):
    keywords = [p.name for p in inspect.signature(cls.__init__).parameters.values()
                if p.name != "self" and p.kind is not p.VAR_KEYWORD]
    assert list(documented_arguments(cls)) == keywords
    assert all(a.description for a in arguments(cls))
    assert {"Description", "Action space", "Observation space", "Rewards", "Episode end", "Arguments",
            "Version history"} <= set(sections(cls))


def test_arguments_table_takes_types_and_defaults_from_the_signature():
    table = {a.name: a for a in arguments(TransportEnv)}
    assert table["reward_mode"].annotation == "str" and table["reward_mode"].default == "'dense'"
    assert table["restitution"].annotation == "float | None" and table["restitution"].default == "None"
    assert table["scenario"].default.startswith("required")


@pytest.mark.parametrize("module, cls", [(impact_env.transport_v0, TransportParallelEnv),
                                         (impact_env.tether_v0, TetherParallelEnv)])
def test_pettingzoo_entry_points_spell_out_the_constructor(module, cls):
    expected = [(p.name, p.default) for p in inspect.signature(cls.__init__).parameters.values() if p.name != "self"]
    expected[0] = (expected[0][0], {"scenario": "corridor", "station": "L"}[expected[0][0]])  # the modules' default
    for name in ("parallel_env", "env", "raw_env"):
        params = inspect.signature(getattr(module, name)).parameters.values()
        assert [(p.name, p.default) for p in params] == expected, name
        assert all(p.kind in (p.POSITIONAL_OR_KEYWORD, p.VAR_KEYWORD) for p in params)
    assert impact_env.parallel_env is impact_env.transport_v0.parallel_env


def test_pettingzoo_metadata_names_the_scenario_and_the_clock_is_on_the_env():
    env = impact_env.transport_v0.parallel_env(scenario="corridor")
    assert env.metadata["name"] == "transport_corridor_v0"
    assert impact_env.transport_v0.parallel_env(scenario="throw_and_catch_exp").metadata["name"] == \
        "transport_throw_and_catch_exp_v0"
    assert (env.dt_s, env.horizon_steps) == (pytest.approx(0.1), 1000)
    tether = impact_env.tether_v0.parallel_env(station="alcove")
    assert tether.metadata["name"] == "tether_alcove_v0" and tether.horizon_steps == 600
    assert TransportParallelEnv.metadata["name"] == "transport_v0"  # the class attribute is not changed


def test_pettingzoo_registry_uses_the_versioned_modules():
    import pettingzoo
    from pettingzoo.env_registry.registration import parallel_registry

    assert parallel_registry["impact_env/transport-v0"].entry_point == "impact_env.transport_v0:parallel_env"
    env = pettingzoo.make("parallel", "impact_env/tether-v0", station="T")
    assert env.metadata["name"] == "tether_T_v0"


def _flags(command: str) -> set[str]:
    from impact_env.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    return {o for a in sub.choices[command]._actions for o in a.option_strings}


@pytest.mark.parametrize("cls, command", [(TransportEnv, "run"), (TetherEnv, "run"), (TransportEnv, "train")])
def test_cli_options_are_the_keyword_names(cls, command):
    """One name per option: ``--reward-mode`` is ``reward_mode=`` (render options have no CLI form)."""
    skip = {"scenario", "station", "render_mode", "render_width_px", "unknown"}
    keywords = [p for p in inspect.signature(cls.__init__).parameters if p not in skip | {"self"}]
    flags = _flags(command)
    missing = [k for k in keywords if "--" + k.replace("_", "-") not in flags]
    assert not missing, f"impact-env {command} lacks options for {missing}"
    assert "--reward" not in flags and "--init-noise" not in flags


def test_renamed_cli_options_say_their_new_name(capsys):
    from impact_env.cli import main

    with pytest.raises(SystemExit):
        main(["run", "corridor", "--init-noise", "0.1"])
    assert "--init-noise is now --initial-position-noise-m" in capsys.readouterr().err


@pytest.mark.parametrize("make, wrong, right", [
    (lambda **kw: gym.make("impact_env/Corridor-v0", **kw), "reward", "reward_mode"),
    (lambda **kw: gym.make("impact_env/Corridor-v0", **kw), "init_noise", "initial_position_noise_m"),
    (lambda **kw: gym.make("impact_env/Corridor-v0", **kw), "thrust_nosie", "thrust_noise"),
    (lambda **kw: gym.make("impact_env/TetherL-v0", **kw), "fidelty", "fidelity"),
    (lambda **kw: impact_env.transport_v0.parallel_env(scenario="corridor", **kw), "max_cycle", "max_cycles"),
    (lambda **kw: impact_env.tether_v0.env(station="L", **kw), "reward", "reward_mode"),
])
def test_an_unknown_keyword_names_the_right_one(make, wrong, right):
    from impact_env.errors import EnvConfigError

    with pytest.raises(EnvConfigError, match=f"no argument '{wrong}' \\(did you mean '{right}'\\?\\)"):
        make(**{wrong: 1})
