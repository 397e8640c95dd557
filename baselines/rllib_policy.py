"""RLlib policies as files that load without running code, and as a controller: ``--controller rllib:PATH``.

An RLlib checkpoint (``Algorithm.save_to_path``) is a tree of pickles (``class_and_ctor_args.pkl``,
``state.pkl``): loading it runs whatever code it names. RLlib's msgpack option does not avoid that either (the
class and its constructor arguments stay pickled, and msgpack-numpy unpickles object arrays). So every
checkpoint that ``impact-env train ... --engine rllib`` writes also gets a ``policy/`` folder of plain data, and
that is all a controller reads:

- ``policy.json`` (format ``impact_env.rllib_policy/1``): the scenario, which policy acts for which robot, the
  network (``model_config``: hidden sizes, activation, shared value layers or not, a free log-std), and per robot the
  observation filter's mean and standard deviation (RLlib's ``MeanStdFilter``; none if training did not
  normalise);
- ``<policy>.npz``: the policy network's inference weights, read with ``allow_pickle=False``.

The network is rebuilt from the known module class (RLlib's default PPO torch module: never a class named in
the file) and the spaces of the scenario's environment, and the weights are checked name by name and shape by
shape before they are set. The controller flies the central Gymnasium env: each robot's policy sees that
robot's observation (own body first, as in the PettingZoo env), filtered as in training, and acts with its
distribution's mode (deterministic, like the SB3 controller). ``PATH`` may be the run folder (its final
``checkpoint/``), a checkpoint folder, or a ``policy/`` folder.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from impact_env.errors import ControllerError, ModelFileError
from impact_env.transport.core import ACTION_PER_ROBOT, OBS_PER_BODY

FORMAT = "impact_env.rllib_policy/1"
POLICY_FOLDER = "policy"
FINAL_CHECKPOINT = "checkpoint"
ACTIVATIONS = ("tanh", "relu")
_MODEL_KEYS = {"fcnet_hiddens", "fcnet_activation", "vf_share_layers", "free_log_std"}


# ------------------------------------------------------------------------------------------------- export


def export_policy(algo: Any, folder: Path, scenario: Any, agent_policies: dict[str, str],
                  model_config: dict[str, Any], observation_filter: bool, env_options: dict[str, Any]) -> Path:
    """Write ``folder/policy.json`` and one ``.npz`` of inference weights per policy of ``algo``; ``scenario`` and
    ``env_options`` are recorded, so that flying it elsewhere is refused or warned about as for SB3 models."""
    from baselines.run_meta import scenario_fingerprint

    folder.mkdir(parents=True, exist_ok=True)
    for policy_id in sorted(set(agent_policies.values())):
        state = algo.get_module(policy_id).get_state(inference_only=True)
        # numpy's stub lets **arrays fill savez's allow_pickle: bool; no parameter of a module is named so
        np.savez(folder / f"{policy_id}.npz", **{k: np.asarray(v) for k, v in state.items()})  # type: ignore[arg-type]
    filters = _filter_statistics(algo, list(agent_policies)) if observation_filter else None
    meta = {"format": FORMAT, "scenario": scenario.name, "scenario_fingerprint": scenario_fingerprint(scenario),
            "env_options": dict(env_options), "agent_policies": agent_policies,
            "model_config": {k: model_config[k] for k in sorted(_MODEL_KEYS)}, "observation_filter": filters}
    (folder / "policy.json").write_text(json.dumps(meta, indent=1))
    return folder


def _filter_statistics(algo: Any, agents: list[str]) -> dict[str, Any]:
    """Per agent the MeanStdFilter's mean and std (merged over the env runners), as RLlib applies them:
    clip((obs - mean) / (std + epsilon), +-clip)."""
    from ray.rllib.utils.filter import SMALL_NUMBER, RunningStat

    state = algo.env_runner.get_state()["env_to_module_connector"]
    filters = next((v for k, v in state.items() if "MeanStdFilter" in k), None)
    if filters is None:
        raise ModelFileError(f"the algorithm has no MeanStdFilter among its env-to-module connectors "
                             f"({sorted(state)}); cannot export the observation statistics")
    out = {}
    for agent in agents:
        f = filters[agent]
        (stat,) = [RunningStat.from_state(s) for s in f["running_stats"]]
        out[agent] = {"mean": np.asarray(stat.mean, dtype=float).tolist(),
                      "std": np.asarray(stat.std, dtype=float).tolist(), "count": int(stat.n),
                      "clip": float(f["clip_by_value"]) if f["clip_by_value"] is not None else None,
                      "epsilon": float(SMALL_NUMBER)}
    return out


# --------------------------------------------------------------------------------------------------- read


def resolve_policy_dir(path: str | Path) -> Path:
    """The ``policy/`` folder of a run folder, a checkpoint folder or the folder itself; a clear error if none."""
    path = Path(path)
    for candidate in (path, path / POLICY_FOLDER, path / FINAL_CHECKPOINT / POLICY_FOLDER):
        if (candidate / "policy.json").is_file():
            return candidate
    if not path.exists():
        raise ModelFileError(f"RLlib checkpoint {str(path)!r} does not exist")
    raise ModelFileError(f"{path} holds no exported RLlib policy (policy.json in it, in {POLICY_FOLDER}/ or in "
                         f"{FINAL_CHECKPOINT}/{POLICY_FOLDER}/): give a run folder or checkpoint written by "
                         "`impact-env train ppo SCENARIO --engine rllib`")


def read_policy_json(folder: Path) -> dict[str, Any]:
    """``policy.json``, every field checked (a malformed file is a :class:`ModelFileError` naming the field)."""
    path = folder / "policy.json"
    try:
        meta = json.loads(path.read_bytes())
    except (OSError, ValueError, RecursionError) as exc:
        raise ModelFileError(f"cannot read {path}: {str(exc)[:200]}") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise ModelFileError(f"{path} is not a {FORMAT} file (written by impact-env train --engine rllib)")
    agents = meta.get("agent_policies")
    if not (isinstance(agents, dict) and agents and all(isinstance(k, str) and isinstance(v, str) and v.isidentifier()
                                                        for k, v in agents.items())):
        raise ModelFileError(f"{path}: agent_policies must map robot names to policy names, got {agents!r}")
    model = meta.get("model_config")
    if not isinstance(model, dict) or set(model) != _MODEL_KEYS:
        raise ModelFileError(f"{path}: model_config must have exactly the keys {sorted(_MODEL_KEYS)}, got {model!r}")
    hidden = model["fcnet_hiddens"]
    if not (isinstance(hidden, list) and hidden and all(type(h) is int and 1 <= h <= 4096 for h in hidden)):
        raise ModelFileError(f"{path}: model_config.fcnet_hiddens must be a list of layer sizes, got {hidden!r}")
    if model["fcnet_activation"] not in ACTIVATIONS or not isinstance(model["vf_share_layers"], bool) \
            or not isinstance(model["free_log_std"], bool):
        raise ModelFileError(f"{path}: model_config.fcnet_activation must be one of {ACTIVATIONS}, and "
                             f"vf_share_layers and free_log_std true or false, got {model!r}")
    for key in ("scenario", "scenario_fingerprint"):
        if meta.get(key) is not None and not isinstance(meta[key], str):
            raise ModelFileError(f"{path}: {key} must be a string, got {meta[key]!r}")
    if not isinstance(meta.get("env_options", {}), dict):
        raise ModelFileError(f"{path}: env_options must be an object, got {meta['env_options']!r}")
    filters = meta.get("observation_filter")
    if filters is not None:
        if not isinstance(filters, dict) or set(filters) != set(agents):
            raise ModelFileError(f"{path}: observation_filter must have one entry per robot {sorted(agents)}")
        for agent, f in filters.items():
            for key in ("mean", "std"):
                values = f.get(key) if isinstance(f, dict) else None
                if not (isinstance(values, list) and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                         and math.isfinite(x) for x in values)):
                    raise ModelFileError(f"{path}: observation_filter.{agent}.{key} must be a list of finite numbers")
            clip = f.get("clip")
            if clip is not None and not (isinstance(clip, (int, float)) and clip > 0):
                raise ModelFileError(f"{path}: observation_filter.{agent}.clip must be a number > 0 or null")
            if not (isinstance(f.get("epsilon"), (int, float)) and f["epsilon"] >= 0):
                raise ModelFileError(f"{path}: observation_filter.{agent}.epsilon must be a number >= 0")
    return meta


def load_weights(path: Path) -> dict[str, np.ndarray]:
    """The arrays of a ``.npz`` file; object arrays (which would need unpickling) are refused."""
    try:
        with np.load(path, allow_pickle=False) as data:
            return {k: np.asarray(data[k]) for k in data.files}
    except (OSError, ValueError, KeyError, EOFError) as exc:
        raise ModelFileError(f"{path} is not a weights file written by impact-env train --engine rllib: "
                             f"{str(exc)[:200]}") from None


# ------------------------------------------------------------------------------------------------ controller


def build_module(observation_space: Any, action_space: Any, model_config: dict[str, Any], weights: dict[str, Any],
                 where: str):
    """RLlib's default PPO torch module for inference, with ``weights`` checked against it and set."""
    try:
        from ray.rllib.algorithms.ppo.torch.default_ppo_torch_rl_module import DefaultPPOTorchRLModule
    except ImportError:
        raise ControllerError("flying an RLlib policy needs RLlib: pip install 'impact_env[ray]'") from None
    module = DefaultPPOTorchRLModule(observation_space=observation_space, action_space=action_space,
                                     inference_only=True, model_config=dict(model_config))
    expected = {k: tuple(v.shape) for k, v in module.get_state().items()}
    given = {k: tuple(np.shape(v)) for k, v in weights.items()}
    if expected != given:
        missing, extra = sorted(set(expected) - set(given)), sorted(set(given) - set(expected))
        wrong = sorted(k for k in set(expected) & set(given) if expected[k] != given[k])
        raise ModelFileError(f"{where} does not fit this scenario's policy network: missing {missing}, unexpected "
                             f"{extra}, wrong shapes {[(k, given[k], expected[k]) for k in wrong]}")
    module.set_state({k: np.asarray(v, dtype=np.float32) for k, v in weights.items()})
    module.eval()
    return module


class RLlibController:
    """Flies an exported RLlib policy (one network per robot, or one shared) in the central Gymnasium env."""

    name = "rllib"

    def __init__(self, scenario: Any, path: str | Path, allow_other_scenario: bool = False) -> None:
        import torch  # noqa: F401 - fail here, with the import error, rather than in act()
        from gymnasium import spaces

        from baselines.run_meta import check_scenario
        from impact_env.transport.core import TransportCore

        if hasattr(scenario, "anchors"):
            raise ControllerError("RLlib policies fly impact scenarios; a tether station takes the expert or an SB3 "
                                  "model")
        self.folder = resolve_policy_dir(path)
        self.meta = read_policy_json(self.folder)
        check_scenario(self.meta, scenario, str(self.folder), allow_other_scenario)
        self._warned = False
        core = TransportCore(scenario)
        robots = [r.name for r in scenario.robots]
        if sorted(self.meta["agent_policies"]) != sorted(robots):
            raise ModelFileError(f"{self.folder}/policy.json is for robots {sorted(self.meta['agent_policies'])}, "
                                 f"scenario {scenario.name!r} has {robots} (trained on {self.meta.get('scenario')!r})")
        obs_space = spaces.Box(core.obs_low, core.obs_high, dtype=np.float32)
        act_space = spaces.Box(-1.0, 1.0, shape=(ACTION_PER_ROBOT,), dtype=np.float32)
        self.robots = robots
        self.n_bodies = core.n_bodies
        self.modules = {}
        for policy_id in sorted(set(self.meta["agent_policies"].values())):
            weights_path = self.folder / f"{policy_id}.npz"
            self.modules[policy_id] = build_module(obs_space, act_space, self.meta["model_config"],
                                                   load_weights(weights_path), str(weights_path))
        self.filters = {}
        for agent, f in (self.meta["observation_filter"] or {}).items():
            mean, std = np.asarray(f["mean"], dtype=np.float32), np.asarray(f["std"], dtype=np.float32)
            if mean.shape != (core.obs_size,) or std.shape != (core.obs_size,):
                raise ModelFileError(f"{self.folder}/policy.json: observation_filter.{agent} has {mean.size} "
                                     f"entries, the scenario's observation {core.obs_size}")
            self.filters[agent] = (mean, std, f["clip"], np.float32(f["epsilon"]))

    def reset(self, env: Any, seed: int | None) -> None:
        if not self._warned:  # flying with other options than trained is an evaluation, never an accident
            import sys

            from baselines.run_meta import option_differences

            self._warned = True
            differences = option_differences(self.meta, env.unwrapped.core)
            if differences:
                print(f"impact-env: warning: {self.folder} was trained with other environment options ("
                      + "; ".join(differences) + ")", file=sys.stderr, flush=True)

    def agent_observations(self, observation: np.ndarray) -> dict[str, np.ndarray]:
        """Each robot's observation (own body first, then the others in order), filtered as in training."""
        obs = np.asarray(observation, dtype=np.float32)
        bodies = obs[:-1].reshape(self.n_bodies, OBS_PER_BODY)
        out = {}
        for i, robot in enumerate(self.robots):
            order = [i] + [j for j in range(self.n_bodies) if j != i]
            x = np.append(bodies[order].reshape(-1), obs[-1]).astype(np.float32)
            if robot in self.filters:
                mean, std, clip, eps = self.filters[robot]
                x = (x - mean) / (std + eps)
                x = np.clip(x, -clip, clip) if clip is not None else x
            out[robot] = x.astype(np.float32)
        return out

    def act(self, observation: np.ndarray, info: dict[str, Any]) -> np.ndarray:
        import torch

        actions = []
        with torch.no_grad():
            for robot, x in self.agent_observations(observation).items():
                module = self.modules[self.meta["agent_policies"][robot]]
                out = module.forward_inference({"obs": torch.from_numpy(x)[None]})
                dist = module.get_inference_action_dist_cls().from_logits(out["action_dist_inputs"])
                actions.append(np.clip(dist.to_deterministic().sample()[0].numpy(), -1.0, 1.0))
        return np.concatenate(actions).astype(np.float32)


def make_rllib_controller(scenario: Any, model: str | None = None, allow_other_scenario: bool = False,
                          **_: Any) -> RLlibController:
    """Factory of the ``impact_env.controllers`` entry point ``rllib``: ``--controller rllib:PATH``."""
    if model is None:
        raise ControllerError("the rllib controller needs a checkpoint: --controller rllib:RUN_OR_CHECKPOINT")
    return RLlibController(scenario, model, allow_other_scenario=allow_other_scenario)
