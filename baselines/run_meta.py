"""Does a saved model fit the environment it is about to fly? The scenario and option checks of a model folder.

``impact-env train`` and ``bc`` write into ``train.json`` the scenario's name, a fingerprint of its content
(:func:`scenario_fingerprint`: every physical and task field, not the description or the file's path) and the
environment options. Before a model flies, :func:`check_scenario` and :func:`option_differences` compare them
with the environment's. The policy:

- **another scenario is refused** (:class:`~impact_env.errors.ModelFileError`): a policy fitted to one world
  flies another with the same observation size without any error and does something meaningless. A model
  folder of an older version without a fingerprint is compared by the scenario's name. ``allow_other_scenario``
  (``--allow-other-scenario``) flies it anyway, for transfer experiments.
- **other environment options give a warning** (printed once): flying a policy trained with thrust noise in
  the nominal environment, or the other way round, is a legitimate evaluation, but it should never be an
  accident.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from typing import Any

import numpy as np

from impact_env.errors import ModelFileError

# the options of TransportEnv that a model folder records, with the environment's defaults
OPTION_DEFAULTS = {"reward_mode": "dense", "fuel_penalty": 0.0, "restitution": None, "thrust_noise": 0.0,
                   "initial_position_noise_m": 0.0}
_NOT_PHYSICAL = {"description", "source", "_formula"}


def _plain(value: Any) -> Any:
    if dataclasses.is_dataclass(value):
        return {f.name: _plain(getattr(value, f.name)) for f in dataclasses.fields(value)
                if f.name not in _NOT_PHYSICAL}
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in sorted(value.items())}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def scenario_fingerprint(scenario: Any) -> str:
    """12 hex digits of a SHA-256 over the scenario's fields (bodies, world, regions, task, timing, restitution)."""
    text = json.dumps(_plain(scenario), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:12]


def check_scenario(meta: dict[str, Any], scenario: Any, where: str, allow_other_scenario: bool = False) -> None:
    """Raise ModelFileError if the model folder's ``train.json`` names another scenario than ``scenario``."""
    if allow_other_scenario or not meta:
        return
    trained_name = meta.get("scenario")
    trained_print = meta.get("scenario_fingerprint")
    if trained_print is not None:
        same = trained_print == scenario_fingerprint(scenario)
    elif trained_name is not None:
        same = trained_name == scenario.name
    else:
        return
    if not same:
        what = f"{trained_name!r}" + (f" (fingerprint {trained_print})" if trained_print else "")
        raise ModelFileError(f"{where} was trained on scenario {what}, not on {scenario.name!r} (fingerprint "
                             f"{scenario_fingerprint(scenario)}): a policy does not transfer to another world. "
                             "Pass --allow-other-scenario to fly it anyway")


def option_differences(meta: dict[str, Any], core: Any) -> list[str]:
    """``["thrust_noise: trained 0.05, flying 0.0", ...]`` for every recorded option the environment differs in."""
    trained = {**OPTION_DEFAULTS, **meta.get("env_options", {})} if meta else None
    if trained is None or "env_options" not in meta:
        return []
    out = []
    for key, default in OPTION_DEFAULTS.items():
        flying = getattr(core, key, default)
        if trained.get(key, default) != flying:
            out.append(f"{key}: trained {trained.get(key, default)!r}, flying {flying!r}")
    return out
