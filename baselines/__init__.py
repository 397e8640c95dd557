"""Learned baselines: stable-baselines3 training, model controllers, behaviour cloning and the benchmark."""

ALGOS = ("ppo", "sac")  # the algorithms `impact-env train` offers (here so that cli.py and train.py share it)
