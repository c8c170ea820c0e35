"""What a model-based SAC run's critics make of its own model buffer, read from a policy
checkpoint: where a diverging critic's values and TD errors come from.

Usage (the test venv's Python):
    .venv/bin/python experiments/critic_checkpoint.py [--root-x INDEX] DATA.hdf5 CHECKPOINT_DIR [...]

CHECKPOINT_DIR is a `fit-policy` checkpoint (`…/policy/checkpoints/epoch-NNNNNN`: its
networks.safetensors, model_buffer.safetensors and state.json). For every transition of the
model buffer it evaluates both critics at (s, a), the Bellman target SAC's critic step regresses
them on (y = r + γ(1 − d)(min Q̄(s′, ã′) − α log π(ã′|s′)), ã′ one draw of the actor at s′ with a
fixed seed; the buffer's rewards are the penalised ones), and prints one row per checkpoint:

- soft reward: mean r − α log π(ã′|s′), what one step pays the critic;
- Q, Q̄′ and y: mean Q₁(s, a), mean min Q̄(s′, ã′), mean target; a critic consistent with
  positive soft rewards has Q̄′ above Q − soft reward (values rise or hold along the rollouts);
- |Q₁ − Q₂|: the twins' median disagreement;
- TD²: mean (Q₁ − y)², the critic's loss on the buffer;
- saturated: the share of rows whose next action has a coordinate past ±0.99, among all and
  among the 2000 rows of largest |TD|;
- outside: the share of next states beyond the data's range widened by 10 % of it;
- frontier: the rows whose next state starts no row of the buffer (a rollout's last step: its
  Q̄′ is the critics' extrapolation, never regressed on), with Q̄′ − Q and TD² on them against
  the other (inner) rows;
- with `--root-x INDEX` (NeoRL's layouts observe root x, at 0): the median slope ∂Q₁/∂x of the
  critic in that observation (a difference of 0.1 at every row) and its mean share of a step,
  ∂Q₁/∂x · (x′ − x). The task's rewards do not depend on where the robot stands, so a slope
  there is one the critic learnt from the data's spread of positions.
"""

import json
import pathlib
import sys

import h5py
import numpy as np
from safetensors.numpy import load_file

BIG_ROWS, SATURATED, MARGIN = 2000, 0.99, 0.1


def mlp(weights, prefix, x):
    layers = sorted({k.split(".layers.")[1].split(".")[0] for k in weights if k.startswith(prefix + ".layers.")}, key=int)
    for i, layer in enumerate(layers):
        x = x @ weights[f"{prefix}.layers.{layer}.weight"] + weights[f"{prefix}.layers.{layer}.bias"]
        if i < len(layers) - 1:
            x = np.maximum(x, 0.0)
    return x


def tanh_gaussian(weights, config, observations, rng):
    """One draw ã = tanh(u) of the actor and log π(ã|s), the box being [−1, 1]."""
    out = mlp(weights, "actor.net", observations)
    act_dim = out.shape[1] // 2
    mean = out[:, :act_dim]
    log_std = np.clip(out[:, act_dim:], config["log_std_min"], config["log_std_max"])
    u = mean + np.exp(log_std) * rng.standard_normal(mean.shape)
    gaussian = -0.5 * ((u - mean) / np.exp(log_std)) ** 2 - log_std - 0.5 * np.log(2 * np.pi)
    # log(1 − tanh²u) = 2·(log 2 − u − softplus(−2u)), as the actor computes it.
    squash = 2 * (np.log(2) - u - np.logaddexp(0, -2 * u))
    return np.tanh(u), gaussian.sum(1) - squash.sum(1)


ROOT_X_STEP = 0.1


def row(data_low, data_high, checkpoint, root_x):
    checkpoint = pathlib.Path(checkpoint)
    weights = load_file(checkpoint / "networks.safetensors")
    buffer = load_file(checkpoint / "model_buffer.safetensors")
    sac = json.loads((checkpoint / "state.json").read_text())["config"]["sac"]
    s, a, r = buffer["observations"], buffer["actions"], buffer["rewards"]
    s_next, done = buffer["next_observations"], buffer["terminals"]
    alpha = float(np.exp(weights["temperature.log_alpha"][0]))
    critic = lambda prefix, obs, act: mlp(weights, prefix, np.concatenate([obs, act], 1))[:, 0]
    q1, q2 = critic("critic.q1", s, a), critic("critic.q2", s, a)
    a_next, log_pi = tanh_gaussian(weights, sac, s_next, np.random.default_rng(0))
    q_next = np.minimum(critic("target_critic.q1", s_next, a_next), critic("target_critic.q2", s_next, a_next))
    soft = r - alpha * log_pi
    y = r + sac["gamma"] * (1 - done) * (q_next - alpha * log_pi)
    td = q1 - y
    big = np.argsort(-np.abs(td))[:BIG_ROWS]
    saturated = np.abs(a_next).max(1) > SATURATED
    span = data_high - data_low
    outside = ((s_next < data_low - MARGIN * span) | (s_next > data_high + MARGIN * span)).any(1)
    starts = {state.tobytes() for state in s}
    frontier = np.array([state.tobytes() not in starts for state in s_next])
    split = lambda v: f"{v[frontier].mean():.3g} / {v[~frontier].mean():.3g}"
    slope = ""
    if root_x is not None:
        moved = s.copy()
        moved[:, root_x] += ROOT_X_STEP
        dq_dx = (critic("critic.q1", moved, a) - q1) / ROOT_X_STEP
        share = dq_dx * (s_next[:, root_x] - s[:, root_x])
        slope = f" {np.median(dq_dx):.2f} / {share.mean():.3f} |"
    return (
        f"| {checkpoint} | {soft.mean():.2f} | {q1.mean():.1f} | {q_next.mean():.1f} | {y.mean():.1f} "
        f"| {np.median(np.abs(q1 - q2)):.2f} | {np.mean(td ** 2):.3g} "
        f"| {saturated.mean():.2f} / {saturated[big].mean():.2f} | {outside.mean():.3f} "
        f"| {frontier.mean():.2f} | {split(q_next - q1)} | {split(td ** 2)} |{slope}"
    )


def main():
    args = sys.argv[1:]
    root_x = None
    if args[:1] == ["--root-x"]:
        root_x, args = int(args[1]), args[2:]
    if len(args) < 2:
        sys.exit(__doc__)
    data, checkpoints = args[0], args[1:]
    with h5py.File(data, "r") as f:
        observations = f["observations"][:]
    low, high = observations.min(0), observations.max(0)
    columns = (
        "| checkpoint | soft reward | Q | Q̄′ | y | median abs(Q₁ − Q₂) | TD² | saturated (all / big TD) "
        "| outside | frontier | Q̄′ − Q (frontier / inner) | TD² (frontier / inner) |"
    )
    if root_x is not None:
        columns += " ∂Q/∂x (median) / its share of a step |"
    print(columns)
    print("|---" * (columns.count("|") - 1) + "|")
    for checkpoint in checkpoints:
        print(row(low, high, checkpoint, root_x))


if __name__ == "__main__":
    main()
