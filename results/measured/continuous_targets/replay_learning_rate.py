"""ERSigma and ER on Pendulum-v1 at learning_rate 0.05 (the class default is 0.2), seeds 0-4, 100,000 steps, median of
20 greedy episodes on an env reset with seed 1000 + seed (benchmarks/continuous_targets.py's protocol otherwise).

    nice -n 10 python results/measured/continuous_targets/replay_learning_rate.py > replay_learning_rate.txt
"""
import statistics
import warnings

import gymnasium as gym
from stable_baselines3.common.evaluation import evaluate_policy
from stable_baselines3.common.monitor import Monitor

from sb3_er import ER, ERSigma

warnings.simplefilter("ignore")
for cls in (ERSigma, ER):
    for seed in range(5):
        model = cls("TileQ", "Pendulum-v1", seed=seed, learning_rate=0.05).learn(100_000)
        env = Monitor(gym.make("Pendulum-v1"))
        env.reset(seed=1000 + seed)
        returns, _ = evaluate_policy(model, env, n_eval_episodes=20, deterministic=True, return_episode_rewards=True)
        print(f"{cls.__name__} learning_rate=0.05 Pendulum-v1 seed {seed}: median {statistics.median(returns):.1f}, "
              f"mean {statistics.fmean(returns):.1f}, values out of range {model.values_out_of_range}", flush=True)
