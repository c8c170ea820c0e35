"""Dataset files for the Rust data tests, written and read the way Python users do.

Usage:
  datasets.py inspect-d4rl FILE OUT.json   what h5py sees in a nuno-written file
  datasets.py inspect-neorl FILE OUT.json  what numpy sees in a nuno-written NeoRL .npz
  datasets.py write-fixtures DIR           D4RL, NeoRL and Minari files, good and bad
"""

import json
import os
import sys

import h5py
import numpy as np

OBS, ACT = 11, 3


def inspect_d4rl(path, out):
    with h5py.File(path, "r") as f:
        report = {
            "keys": sorted(f.keys()),
            "infos": sorted(f["infos"].keys()),
            "metadata": {k: f["metadata"][k][()].decode() for k in f["metadata"].keys()},
            "dtypes": {k: str(f[k].dtype) for k in ["observations", "actions", "rewards",
                                                   "next_observations", "terminals", "timeouts"]},
            "shapes": {k: list(f[k].shape) for k in ["observations", "actions", "rewards",
                                                    "next_observations", "terminals", "timeouts",
                                                    "infos/qpos", "infos/qvel",
                                                    "infos/action_log_probs"] if k in f},
            "compression": f["observations"].compression,
        }
        obs, nxt = f["observations"][:], f["next_observations"][:]
        ends = f["terminals"][:] | f["timeouts"][:]
        inside = np.flatnonzero(~ends[:-1])
        report["continuity_max_error"] = float(np.abs(nxt[inside] - obs[inside + 1]).max())
        # infos/qpos is the MuJoCo state at observations[i]: obs = qpos[1:] ++ clip(qvel).
        qpos, qvel = f["infos/qpos"][:], f["infos/qvel"][:]
        report["qpos_max_error"] = float(np.abs(obs[:, :5] - qpos[:, 1:]).max())
        report["qvel_max_error"] = float(np.abs(obs[:, 5:] - np.clip(qvel, -10, 10)).max())
        report["return_sum"] = float(f["rewards"][:].astype(np.float64).sum())
    with open(out, "w") as fh:
        json.dump(report, fh)


def inspect_neorl(path, out):
    with np.load(path) as f:
        report = {
            "keys": sorted(f.files),
            "dtypes": {k: str(f[k].dtype) for k in f.files},
            "shapes": {k: list(f[k].shape) for k in f.files},
            "index": f["index"].tolist(),
            "done_sum": float(f["done"].sum()),
            "return_sum": float(f["reward"].astype(np.float64).sum()),
        }
    with open(out, "w") as fh:
        json.dump(report, fh)


def trajectories(rng, lengths, width=OBS):
    """Continuous trajectories: next_obs[i] == obs[i + 1] inside each."""
    obs, nxt = [], []
    for n in lengths:
        states = rng.standard_normal((n + 1, width))
        obs.append(states[:-1])
        nxt.append(states[1:])
    return np.concatenate(obs), np.concatenate(nxt)


def d4rl(path, obs, nxt, terminals, timeouts, rng, overrides=None):
    n = len(obs)
    data = {
        "observations": obs,
        "actions": rng.uniform(-1, 1, (n, ACT)),
        "rewards": rng.standard_normal(n),
        "terminals": terminals,
        "timeouts": timeouts,
        "next_observations": nxt,
    }
    data.update(overrides or {})
    with h5py.File(path, "w") as f:
        for key, value in data.items():
            if value is not None:
                f.create_dataset(key, data=value)


def write_fixtures(d):
    rng = np.random.default_rng(0)
    lengths = [5, 7, 4]
    obs, nxt = trajectories(rng, lengths)
    n = len(obs)
    ends = np.cumsum(lengths) - 1
    terminals = np.zeros(n, bool)
    terminals[ends[0]] = True
    timeouts = np.zeros(n, bool)
    timeouts[ends[2]] = True
    # ends[1] is flagged nowhere: only continuity reveals it (unreliable timeouts).
    d4rl(f"{d}/quirky.hdf5", obs.astype(np.float64), nxt, terminals, timeouts, rng,
         {"rewards": rng.standard_normal((n, 1))})
    # No next_observations: the last step of each flagged trajectory has no next state.
    flagged = timeouts.copy()
    flagged[ends[1]] = True
    d4rl(f"{d}/no_next.hdf5", obs, nxt, terminals, flagged, rng, {"next_observations": None})
    # Older files without timeouts.
    d4rl(f"{d}/no_timeouts.hdf5", obs, nxt, terminals, timeouts, rng, {"timeouts": None})

    # Bad files.
    d4rl(f"{d}/missing_actions.hdf5", obs, nxt, terminals, timeouts, rng, {"actions": None})
    d4rl(f"{d}/short_rewards.hdf5", obs, nxt, terminals, timeouts, rng, {"rewards": np.zeros(n - 1)})
    d4rl(f"{d}/wide_obs.hdf5", np.zeros((n, 17)), np.zeros((n, 17)), terminals, timeouts, rng)
    bad = obs.copy()
    bad[6, 2] = np.nan
    d4rl(f"{d}/nan_obs.hdf5", bad, nxt, terminals, timeouts, rng)
    d4rl(f"{d}/empty.hdf5", np.zeros((0, OBS)), np.zeros((0, OBS)), np.zeros(0, bool),
         np.zeros(0, bool), rng, {"actions": np.zeros((0, ACT)), "rewards": np.zeros(0)})
    d4rl(f"{d}/flat_obs.hdf5", obs.reshape(-1), nxt, terminals, timeouts, rng)
    with open(f"{d}/garbage.hdf5", "wb") as fh:
        fh.write(b"this is not an HDF5 file" * 10)

    # NeoRL: index holds trajectory starts; obs include root x (12 wide for hopper).
    starts = np.concatenate([[0], np.cumsum(lengths)[:-1]])
    neorl_obs, neorl_next = (a.astype(np.float32) for a in trajectories(rng, lengths, OBS + 1))
    done = np.zeros((n, 1), np.float32)
    done[ends[0]] = 1.0
    np.savez_compressed(f"{d}/neorl.npz", obs=neorl_obs, next_obs=neorl_next,
                        action=rng.uniform(-1, 1, (n, ACT)).astype(np.float32),
                        reward=rng.standard_normal((n, 1)).astype(np.float32), done=done,
                        index=starts.astype(np.int64))
    np.savez(f"{d}/neorl_missing.npz", obs=neorl_obs, action=np.zeros((n, ACT)))

    # Minari: one group per episode, observations one row longer than actions.
    os.makedirs(f"{d}/minari/data", exist_ok=True)
    with h5py.File(f"{d}/minari/data/main_data.hdf5", "w") as f:
        f.attrs["total_episodes"] = len(lengths)
        for e, length in enumerate(lengths):
            g = f.create_group(f"episode_{e}")
            g.create_dataset("observations", data=rng.standard_normal((length + 1, OBS)))
            g.create_dataset("actions", data=rng.uniform(-1, 1, (length, ACT)))
            g.create_dataset("rewards", data=np.full(length, float(e)))
            term = np.zeros(length, bool)
            term[-1] = e == 0
            trunc = np.zeros(length, bool)
            trunc[-1] = e == 1  # episode 2 ends with neither flag
            g.create_dataset("terminations", data=term)
            g.create_dataset("truncations", data=trunc)
            g.create_group("infos")


if __name__ == "__main__":
    if sys.argv[1] == "inspect-d4rl":
        inspect_d4rl(sys.argv[2], sys.argv[3])
    elif sys.argv[1] == "inspect-neorl":
        inspect_neorl(sys.argv[2], sys.argv[3])
    elif sys.argv[1] == "write-fixtures":
        write_fixtures(sys.argv[2])
    else:
        sys.exit(f"unknown command {sys.argv[1]}")
