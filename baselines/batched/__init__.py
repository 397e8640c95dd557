"""Trainers on the batched torch world (:mod:`impact_env.transport.batched`): BenchMARL's MAPPO and IPPO
(:mod:`baselines.batched.marl`, with the task class of :mod:`baselines.batched.benchmarl_task`) and
stable-baselines3's PPO through the world's ``VecEnv`` (:mod:`baselines.batched.sb3_ppo`). The runs at scale
are :mod:`benchmarks.rl_at_scale`'s."""
