"""The batched world as a TorchRL ``EnvBase`` with one multi-agent group, as TorchRL's ``VmasEnv`` provides.

    from impact_env.transport.batched.torchrl_env import TransportTorchRLEnv
    from torchrl.envs.utils import check_env_specs

    env = TransportTorchRLEnv("corridor", num_envs=64)
    check_env_specs(env)
    rollout = env.rollout(10)          # a TensorDict of batch size [64, 10]

Keys (TorchRL's MARL convention: one group, ``agents``, holding a tensor per agent; N envs, R robots):

- ``("agents", "observation")`` [N, R, 7 B + 1] float32: each robot's own observation (its body first), as
  ``TransportParallelEnv`` gives it; ``("agents", "action")`` [N, R, 3] in [-1, 1];
- ``("agents", "reward")`` [N, R, 1]: the team reward (the Gym env's reward, the same for every robot);
- ``("agents", "done" | "terminated" | "truncated")`` [N, R, 1] and the same at the root [N, 1]: the task's
  horizon ends the episode of every robot at once (a termination: ``truncated`` stays False);
- ``"state"`` [N, 7 B + 1]: the central observation, for centralised critics (MAPPO, BenchMARL's ``state_spec``);
- ``("agents", "info", "robustness" | "is_success")`` [N, R, 1]: the online STL robustness (m) and its sign.

Partial resets follow TorchRL's ``"_reset"`` masks (a collector resets the envs that are done); ``set_seed(s)``
seeds the next reset (env i gets seed s + i, the batched world's convention). Needs ``torchrl`` (the ``[marl]``
extra: torchrl 0.11.1 with BenchMARL 1.5.2, or torchrl 0.14 alone; see docs/batched.md).
"""

from __future__ import annotations

from typing import Any

import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Bounded, Categorical, Composite, Unbounded
from torchrl.envs import EnvBase

from impact_env.transport.batched.world import BatchedTransportWorld
from impact_env.transport.scenario import Scenario

GROUP = "agents"


class TransportTorchRLEnv(EnvBase):
    """``num_envs`` envs of one scenario for TorchRL; see the module docstring for the keys.

    Args:
        scenario: a Scenario, a shipped scenario name or a path to a TOML file.
        num_envs: the batch size N.
        device: torch device of the world and of every tensor (default CPU).
        **world_options: :class:`~impact_env.transport.batched.BatchedTransportWorld`'s options (``dtype``,
            ``reward_mode``, ``thrust_noise``, ``initial_position_noise_m``, ``compile`` ...).
    """

    batch_locked = True

    def __init__(self, scenario: Scenario | str, num_envs: int, *, device: torch.device | str | None = None,
                 **world_options: Any) -> None:
        self.world = BatchedTransportWorld(scenario, num_envs, device=device, **world_options)
        world = self.world
        super().__init__(device=world.device, batch_size=torch.Size([num_envs]))
        self.scenario = world.scenario
        R, obs_size = world.n_robots, world.obs_size
        self.agent_names = [r.name for r in self.scenario.robots]
        self.group_map = {GROUP: list(self.agent_names)}
        dev = world.device
        low = torch.as_tensor(world.obs_low, device=dev)
        high = torch.as_tensor(world.obs_high, device=dev)
        flag = {"n": 2, "dtype": torch.bool, "device": dev}
        agent_obs = Bounded(low.expand(R, obs_size), high.expand(R, obs_size), shape=(R, obs_size),
                            dtype=torch.float32, device=dev)
        info = Composite({"robustness": Unbounded(shape=(R, 1), dtype=world.dtype, device=dev),
                          "is_success": Categorical(shape=(R, 1), **flag)}, shape=(R,), device=dev)
        self.full_observation_spec_unbatched = Composite(
            {GROUP: Composite({"observation": agent_obs, "info": info}, shape=(R,), device=dev),
             "state": Bounded(low, high, shape=(obs_size,), dtype=torch.float32, device=dev)}, device=dev)
        self.full_action_spec_unbatched = Composite(
            {GROUP: Composite({"action": Bounded(-1.0, 1.0, shape=(R, 3), dtype=world.dtype, device=dev)},
                              shape=(R,), device=dev)}, device=dev)
        self.full_reward_spec_unbatched = Composite(
            {GROUP: Composite({"reward": Unbounded(shape=(R, 1), dtype=world.dtype, device=dev)}, shape=(R,),
                              device=dev)}, device=dev)
        done = {k: Categorical(shape=(1,), **flag) for k in ("done", "terminated", "truncated")}
        agent_done = {k: Categorical(shape=(R, 1), **flag) for k in ("done", "terminated", "truncated")}
        self.full_done_spec_unbatched = Composite(
            {**done, GROUP: Composite(agent_done, shape=(R,), device=dev)}, device=dev)
        self._next_seed: int | None = None

    # ---------------------------------------------------------------------------------------- helpers
    def _out(self, reward: torch.Tensor | None, terminated: torch.Tensor, truncated: torch.Tensor) -> TensorDict:
        world = self.world
        N, R = world.num_envs, world.n_robots
        done = terminated | truncated
        group = {"observation": world.agent_observations(),
                 "info": TensorDict({"robustness": world.robustness.reshape(N, 1, 1).expand(N, R, 1),
                                     "is_success": (world.robustness > 0.0).reshape(N, 1, 1).expand(N, R, 1)},
                                    batch_size=(N, R), device=world.device),
                 "done": done.reshape(N, 1, 1).expand(N, R, 1),
                 "terminated": terminated.reshape(N, 1, 1).expand(N, R, 1),
                 "truncated": truncated.reshape(N, 1, 1).expand(N, R, 1)}
        if reward is not None:
            group["reward"] = reward.reshape(N, 1, 1).expand(N, R, 1)
        return TensorDict({GROUP: TensorDict(group, batch_size=(N, R), device=world.device), "state": world.state(),
                           "done": done.reshape(N, 1), "terminated": terminated.reshape(N, 1),
                           "truncated": truncated.reshape(N, 1)}, batch_size=(N,), device=world.device)

    def _reset_mask(self, tensordict: TensorDictBase | None) -> torch.Tensor | None:
        if tensordict is None:
            return None
        mask = tensordict.get("_reset", None)
        if mask is not None:
            mask = mask.reshape(self.world.num_envs, -1).any(-1)
        group_mask = tensordict.get((GROUP, "_reset"), None)
        if group_mask is not None:
            group_mask = group_mask.reshape(self.world.num_envs, -1).any(-1)
            mask = group_mask if mask is None else mask | group_mask
        return mask

    # ------------------------------------------------------------------------------------------- API
    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs: Any) -> TensorDictBase:
        mask = self._reset_mask(tensordict)
        seeds, self._next_seed = self._next_seed, None
        self.world.reset(seeds=seeds, mask=mask)
        # an env not in the mask was not done (TorchRL resets exactly the done ones), so all flags are False
        none = torch.zeros(self.world.num_envs, dtype=torch.bool, device=self.world.device)
        return self._out(None, none, none)

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        action = tensordict.get((GROUP, "action"))
        _, reward, terminated, truncated, _ = self.world.step(action)
        return self._out(reward, terminated, truncated)

    def _set_seed(self, seed: int | None) -> None:
        self._next_seed = None if seed is None else int(seed)

    def render_rgb(self, env_index: int = 0, width_px: int = 600):
        """A uint8 (H, W, 3) frame of one env (:meth:`BatchedTransportWorld.render_rgb`)."""
        return self.world.render_rgb(env_index, width_px)
