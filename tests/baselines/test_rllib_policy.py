"""Exported RLlib policies are plain data: policy.json is checked field by field, weights load without pickles,
and a network that does not fit the scenario is refused with the names and shapes that differ."""

from __future__ import annotations

import json

import numpy as np
import pytest

from baselines.rllib_policy import load_weights, read_policy_json, resolve_policy_dir
from impact_env.controllers import make_controller
from impact_env.errors import ModelFileError
from impact_env.transport.scenario import load_scenario

GOOD = {"format": "impact_env.rllib_policy/1", "scenario": "throw_and_catch_exp",
        "agent_policies": {"R1": "R1", "R2": "R2"},
        "model_config": {"fcnet_hiddens": [16, 16], "fcnet_activation": "tanh", "vf_share_layers": False,
                         "free_log_std": True},
        "observation_filter": None}


def _write(folder, **changes):
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "policy.json").write_text(json.dumps({**GOOD, **changes}))
    return folder


def test_a_run_folder_a_checkpoint_or_the_policy_folder_resolve_to_the_export(tmp_path):
    policy = _write(tmp_path / "run" / "checkpoint" / "policy")
    for path in (tmp_path / "run", tmp_path / "run" / "checkpoint", policy):
        assert resolve_policy_dir(path) == policy
    with pytest.raises(ModelFileError, match="does not exist"):
        resolve_policy_dir(tmp_path / "nowhere")
    with pytest.raises(ModelFileError, match="holds no exported RLlib policy"):
        resolve_policy_dir(tmp_path)
    assert read_policy_json(policy)["agent_policies"] == {"R1": "R1", "R2": "R2"}


@pytest.mark.parametrize("changes, message", [
    ({"format": "something/2"}, "is not a impact_env.rllib_policy/1 file"),
    ({"agent_policies": {"R1": "os.system"}}, "agent_policies must map robot names to policy names"),
    ({"model_config": {"fcnet_hiddens": [16]}}, "model_config must have exactly the keys"),
    ({"model_config": {**GOOD["model_config"], "fcnet_hiddens": [0]}}, "fcnet_hiddens must be a list of layer"),
    ({"model_config": {**GOOD["model_config"], "fcnet_activation": "gelu"}}, "fcnet_activation must be one of"),
    ({"observation_filter": {"R1": {}}}, "observation_filter must have one entry per robot"),
    ({"observation_filter": {r: {"mean": [0.0], "std": ["x"], "clip": 10, "epsilon": 1e-8} for r in ("R1", "R2")}},
     "observation_filter.R1.std must be a list of finite numbers"),
])
def test_a_malformed_policy_json_names_its_field(tmp_path, changes, message):
    with pytest.raises(ModelFileError, match=message):
        read_policy_json(_write(tmp_path, **changes))


def test_weights_never_unpickle(tmp_path):
    np.savez(tmp_path / "ok.npz", w=np.ones((2, 3), dtype=np.float32))
    assert load_weights(tmp_path / "ok.npz")["w"].shape == (2, 3)
    np.savez(tmp_path / "objects.npz", w=np.array([{"code": 1}], dtype=object))  # would need pickle to load
    with pytest.raises(ModelFileError, match="is not a weights file"):
        load_weights(tmp_path / "objects.npz")


def test_the_rllib_controller_is_named_with_its_checkpoint(tmp_path):
    with pytest.raises(ModelFileError, match="holds no exported RLlib policy"):
        make_controller(f"rllib:{tmp_path}", load_scenario("throw_and_catch_exp"))


def test_a_network_that_does_not_fit_the_scenario_is_refused(tmp_path):
    pytest.importorskip("ray.rllib")
    from gymnasium import spaces
    from ray.rllib.algorithms.ppo.torch.default_ppo_torch_rl_module import DefaultPPOTorchRLModule

    from baselines.rllib_policy import build_module

    obs, act = spaces.Box(-1, 1, (22,), np.float32), spaces.Box(-1, 1, (3,), np.float32)
    model = GOOD["model_config"]
    state = DefaultPPOTorchRLModule(observation_space=obs, action_space=act, inference_only=True,
                                    model_config=dict(model)).get_state()
    module = build_module(obs, act, model, state, "w.npz")
    assert all(np.array_equal(v, state[k]) for k, v in module.get_state().items())
    wider = spaces.Box(-1, 1, (29,), np.float32)  # a scenario with one more body
    with pytest.raises(ModelFileError, match=r"w.npz does not fit .* wrong shapes \[\('encoder.actor_encoder"):
        build_module(wider, act, model, state, "w.npz")
    with pytest.raises(ModelFileError, match=r"missing \['pi.net.mlp.0.bias'\]"):
        build_module(obs, act, model, {k: v for k, v in state.items() if k != "pi.net.mlp.0.bias"}, "w.npz")
