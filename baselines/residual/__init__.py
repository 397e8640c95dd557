"""A residual policy: a learned correction added to the expert's command (``impact-env residual SCENARIO``).

:mod:`baselines.residual.env` holds the world (:class:`ResidualEnv`: the expert flies the pymunk env and the
agent's action adds ``scale * a`` to its command) and the controller that flies a trained correction
(:class:`ResidualController`); :mod:`baselines.residual.train` trains one with stable-baselines3's PPO under
post-impact velocity noise, resumably; :mod:`baselines.residual.cli` is the command. The benchmark against the
expert alone on the same seeds is ``python -m benchmarks.residual``.
"""

from baselines.residual.env import DEFAULT_SCALE, ResidualController, ResidualEnv, compose, residual_spaces
from baselines.residual.train import TRAINING_NOISE, ResidualConfig, build_expert, train_residual

__all__ = ["DEFAULT_SCALE", "TRAINING_NOISE", "ResidualConfig", "ResidualController", "ResidualEnv", "build_expert",
           "compose", "residual_spaces", "train_residual"]
