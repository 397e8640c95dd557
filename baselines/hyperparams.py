"""rl-baselines3-zoo hyperparameter files, read without eval.

rl-zoo writes ``policy_kwargs`` as a Python expression (``"dict(net_arch=[64, 64])"``) and evaluates it; here
it is parsed with ``ast`` and only ``dict(...)`` of literals (and ``nn.ReLU``-style activation names) is
accepted. Schedules ``lin_3e-4`` become SB3's linear schedules.
"""

from __future__ import annotations

import ast
from importlib import resources
from pathlib import Path
from typing import Any

import yaml

from impact_env.errors import HyperparameterError

ACTIVATIONS = {"nn.ReLU": "ReLU", "nn.Tanh": "Tanh", "nn.ELU": "ELU", "nn.LeakyReLU": "LeakyReLU"}
ZOO_ONLY = {"n_envs", "n_timesteps", "policy", "normalize", "frame_stack", "env_wrapper", "callback"}


def load(algo: str, env_id: str, path: str | Path | None = None) -> dict[str, Any]:
    """The entry for ``env_id`` in ``baselines/hyperparams/<algo>.yml`` (or ``path``), parsed."""
    text = (Path(path).read_text() if path else
            (resources.files("baselines") / "hyperparams" / f"{algo}.yml").read_text())
    try:
        table = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise HyperparameterError(f"{path or algo + '.yml'}: not valid YAML: {exc}") from None
    if env_id not in table:
        raise HyperparameterError(f"no {algo} hyperparameters for {env_id!r}; entries: {', '.join(table)}")
    entry = dict(table[env_id])
    if "policy_kwargs" in entry and isinstance(entry["policy_kwargs"], str):
        entry["policy_kwargs"] = parse_policy_kwargs(entry["policy_kwargs"])
    for key in ("learning_rate", "clip_range"):
        if isinstance(entry.get(key), str):
            entry[key] = parse_schedule(entry[key])
    return entry


def parse_policy_kwargs(text: str) -> dict[str, Any]:
    """``"dict(net_arch=[64, 64], activation_fn=nn.Tanh)"`` -> a dict, without evaluating code."""
    try:
        node = ast.parse(text, mode="eval").body
    except SyntaxError as exc:
        raise HyperparameterError(f"policy_kwargs {text!r} is not an expression: {exc}") from None
    if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "dict") or node.args:
        raise HyperparameterError(f"policy_kwargs must look like dict(key=value, ...), got {text!r}")
    out: dict[str, Any] = {}
    for kw in node.keywords:
        if kw.arg is None:
            raise HyperparameterError(f"policy_kwargs must look like dict(key=value, ...), got {text!r}")
        src = ast.unparse(kw.value)
        if src in ACTIVATIONS:
            import torch.nn as nn

            out[kw.arg] = getattr(nn, ACTIVATIONS[src])
            continue
        try:
            out[kw.arg] = ast.literal_eval(kw.value)
        except ValueError:
            raise HyperparameterError(f"policy_kwargs.{kw.arg} = {src} is not a literal") from None
    return out


def parse_schedule(text: str):
    """``lin_3e-4`` -> a linear schedule from 3e-4 to 0; a plain number string -> that float."""
    if text.startswith("lin_"):
        start = float(text[4:])

        def schedule(progress_remaining: float) -> float:
            return progress_remaining * start

        return schedule
    try:
        return float(text)
    except ValueError:
        raise HyperparameterError(f"unknown schedule {text!r} (use a number or lin_<number>)") from None


def algorithm_kwargs(entry: dict[str, Any]) -> dict[str, Any]:
    """The entry without rl-zoo's own keys: what the SB3 algorithm's constructor takes."""
    return {k: v for k, v in entry.items() if k not in ZOO_ONLY}
