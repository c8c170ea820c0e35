"""Peer for benches/env_step.rs: Gymnasium `*-v4` steps/s on one core.

Usage: gymnasium_step_speed.py TASK STEPS -> prints steps/s
"""

import sys
import time

import gymnasium as gym
import numpy as np

IDS = {"hopper": "Hopper-v4", "halfcheetah": "HalfCheetah-v4", "walker2d": "Walker2d-v4"}

task, steps = sys.argv[1], int(sys.argv[2])
env = gym.make(IDS[task])
rng = np.random.default_rng(0)
actions = rng.uniform(-1.0, 1.0, size=(steps, env.action_space.shape[0]))
env.reset(seed=0)
start = time.perf_counter()
for action in actions:
    _, _, terminated, truncated, _ = env.step(action)
    if terminated or truncated:
        env.reset()
print(steps / (time.perf_counter() - start))
