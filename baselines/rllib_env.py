"""The PettingZoo transport env as an RLlib multi-agent env (``impact-env train ppo SCENARIO --engine rllib``).

RLlib's env runners (separate processes, possibly on other nodes) build the env by name from a creator that
Ray registers once per driver: :func:`register` names :func:`make_env`, which wraps
:func:`impact_env.transport.pettingzoo_env.parallel_env` in RLlib's own PettingZoo wrapper. The wrapper lists
the agents from a set, so their order would depend on the process's hash seed; :class:`TransportMultiAgentEnv`
keeps the scenario's robot order instead. The ``env_config`` dict is the env's keyword arguments, passed
through unchanged: ``scenario`` (a loaded Scenario, so that it reaches env runners on other nodes whole) and
the options (reward mode, fuel penalty, noise, restitution).
"""

from __future__ import annotations

from collections.abc import Hashable
from typing import Any

ENV_NAME = "impact_env_transport_parallel"


def _wrapper_class():
    from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv

    class TransportMultiAgentEnv(ParallelPettingZooEnv):
        """RLlib's ParallelPettingZooEnv with the agents in the scenario's robot order, and per-agent spaces."""

        def __init__(self, env) -> None:
            super().__init__(env)
            self.possible_agents = list(env.possible_agents)
            self.agents = list(self.possible_agents)
            self.observation_spaces = {a: env.observation_space(a) for a in self.possible_agents}
            self.action_spaces = {a: env.action_space(a) for a in self.possible_agents}

    return TransportMultiAgentEnv


def make_env(env_config: dict[str, Any]):
    """The env of one RLlib env runner: the transport ParallelEnv with ``env_config`` as its keywords. The
    runner's process drops RLlib's notices from here on (:mod:`baselines.rllib_notices`)."""
    from baselines.rllib_notices import quiet_notices
    from impact_env.transport.pettingzoo_env import parallel_env

    quiet_notices()
    return _wrapper_class()(parallel_env(**dict(env_config)))


def register() -> str:
    """Register :func:`make_env` with Ray under :data:`ENV_NAME` (idempotent); returns the name."""
    from ray.tune.registry import register_env

    register_env(ENV_NAME, make_env)
    return ENV_NAME


def agent_to_policy(agent_id: Hashable, episode: Any = None, **_: Any) -> str:
    """Independent policies: each robot its own policy, named after it (RLlib's ``policy_mapping_fn``)."""
    return str(agent_id)


def shared_policy(agent_id: Hashable, episode: Any = None, **_: Any) -> str:
    """Parameter sharing: every robot acts with the one policy ``shared``."""
    return "shared"


def observation_filter(env: Any = None, spaces: Any = None, device: Any = None):
    """RLlib's running mean/std observation filter per agent (the counterpart of SB3's VecNormalize on
    observations); its statistics are exported with the policy (:mod:`baselines.rllib_policy`)."""
    from ray.rllib.connectors.env_to_module import MeanStdFilter

    return MeanStdFilter(multi_agent=True)
