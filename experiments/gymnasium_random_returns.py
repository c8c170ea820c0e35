"""The `random` score references of the tasks D4RL has none for (src/envs/task.rs):
the mean return of uniformly random actions over 1000 Gymnasium `*-v4` episodes,
seeds 0-999 (the reset's and the action space's). Run with the test venv:

    .venv/bin/python experiments/gymnasium_random_returns.py

Printed on 2026-12-03 (gymnasium 1.2.2, mujoco 3.17.0):
    Swimmer-v4 mean 0.485732 std 10.2675 n 1000
    InvertedPendulum-v4 mean 6.020000 std 3.4991 n 1000
    Ant-v4 mean -61.327469 std 100.6760 n 1000
"""

import gymnasium as gym
import numpy as np

for env_id in ["Swimmer-v4", "InvertedPendulum-v4", "Ant-v4"]:
    env = gym.make(env_id)
    returns = []
    for seed in range(1000):
        env.reset(seed=seed)
        env.action_space.seed(seed)
        total, done = 0.0, False
        while not done:
            _, reward, terminated, truncated, _ = env.step(env.action_space.sample())
            total += reward
            done = terminated or truncated
        returns.append(total)
    print(f"{env_id} mean {np.mean(returns):.6f} std {np.std(returns):.4f} n {len(returns)}")
