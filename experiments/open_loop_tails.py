"""Per-window open-loop error of a served model, by quantile: what a mean over
windows (`nuno-trainer analyze`) hides when a few rollouts run away.

Usage (a server running the model, the test venv's Python):
    nuno-server --models DIR --addr 127.0.0.1:18099 &
    .venv/bin/python experiments/open_loop_tails.py http://127.0.0.1:18099 MODEL DATA.hdf5 [NOISE ...]

Draws 200 windows of 10 steps inside the dataset's episodes (seed 0),
rolls one particle per window along the logged actions at each noise scale
(`noise_scale` of the rollout route: 1 samples Σ, 0 follows the drift), and
prints the median, 90th percentile and maximum over windows of the RMSE in
units of each observation's std, per step.
"""

import json
import sys
import urllib.request

import h5py
import numpy as np

HORIZON, WINDOWS = 10, 200


def main():
    url, model, data = sys.argv[1:4]
    noises = [float(n) for n in sys.argv[4:]] or [1.0, 0.0]
    with h5py.File(data, "r") as f:
        obs, act = f["observations"][:], f["actions"][:]
        ends = f["terminals"][:].astype(bool) | f["timeouts"][:].astype(bool)
    # A window's start needs HORIZON more steps in its episode.
    episode = np.concatenate([[0], np.cumsum(ends)[:-1]])
    later = np.arange(len(obs)) + HORIZON
    valid = np.flatnonzero((later < len(obs)) & (episode[np.minimum(later, len(obs) - 1)] == episode))
    idx = np.random.default_rng(0).choice(valid, WINDOWS, replace=False)
    std = obs.std(0)
    for noise in noises:
        body = {
            "states": obs[idx].tolist(),
            "actions": [act[i : i + HORIZON].tolist() for i in idx],
            "horizon": HORIZON,
            "particles": 1,
            "seed": 0,
            "noise_scale": noise,
        }
        request = urllib.request.Request(
            f"{url}/v1/models/{model}/rollout",
            data=json.dumps(body).encode(),
            headers={"content-type": "application/json"},
        )
        trajectories = json.load(urllib.request.urlopen(request))["trajectories"]
        errors = np.full((WINDOWS, HORIZON), np.nan)
        for w, t in enumerate(trajectories):
            states = np.array(t["states"])
            for k in range(1, len(states)):
                errors[w, k - 1] = np.sqrt((((states[k] - obs[idx[w] + k]) / std) ** 2).mean())
        print(f"noise_scale {noise}")
        print("  median", np.round(np.nanmedian(errors, 0), 3).tolist())
        print("  p90   ", np.round(np.nanpercentile(errors, 90, 0), 3).tolist())
        print("  max   ", np.round(np.nanmax(errors, 0), 1).tolist())


if __name__ == "__main__":
    main()
