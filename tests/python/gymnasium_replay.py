"""Replays episodes in Gymnasium's MuJoCo `*-v4` tasks for the Rust parity test.

Usage: gymnasium_replay.py IN.json OUT.json

IN holds episodes as the Rust tasks ran them: task, observation layout, time
limit, the full start state (qpos, qvel) and the actions. Each is replayed from
that state through `gymnasium.make` (so the TimeLimit wrapper is real), and OUT
gets what Gymnasium reports: its initial state, the first observation, and per
step the observation, reward, terminated and truncated flags.
"""

import json
import sys

import gymnasium as gym
import numpy as np

IDS = {
    "hopper": "Hopper-v4",
    "halfcheetah": "HalfCheetah-v4",
    "walker2d": "Walker2d-v4",
    "swimmer": "Swimmer-v4",
    "invertedpendulum": "InvertedPendulum-v4",
    "ant": "Ant-v4",
}
# InvertedPendulum observes its whole qpos and takes no such keyword.
FULL_QPOS_ONLY = {"invertedpendulum"}


def replay(episode):
    layout = {}
    if episode["task"] not in FULL_QPOS_ONLY:
        layout["exclude_current_positions_from_observation"] = episode["layout"] == "d4rl"
    env = gym.make(
        IDS[episode["task"]], max_episode_steps=episode["max_episode_steps"], **layout
    )
    env.reset(seed=0)
    sim = env.unwrapped
    sim.set_state(np.asarray(episode["qpos"]), np.asarray(episode["qvel"]))
    out = {
        "init_qpos": sim.init_qpos.tolist(),
        "init_qvel": sim.init_qvel.tolist(),
        "first_observation": sim._get_obs().tolist(),
        "observations": [],
        "rewards": [],
        "terminated": [],
        "truncated": [],
    }
    for action in episode["actions"]:
        obs, reward, terminated, truncated, _ = env.step(np.asarray(action, dtype=np.float64))
        out["observations"].append(obs.tolist())
        out["rewards"].append(float(reward))
        out["terminated"].append(bool(terminated))
        out["truncated"].append(bool(truncated))
        if terminated or truncated:
            break
    env.close()
    return out


def main():
    with open(sys.argv[1]) as f:
        episodes = json.load(f)["episodes"]
    with open(sys.argv[2], "w") as f:
        json.dump({"episodes": [replay(e) for e in episodes]}, f)


if __name__ == "__main__":
    main()
