"""Calls a running nuno-server through the installed `nuno` package
(clients/python) and checks its generated layer is current.

usage: nuno_package.py BASE_URL  (run in a scratch directory; writes result.json)
"""
import filecmp
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

import nuno

base = sys.argv[1]
work = Path.cwd()
package = Path(__file__).resolve().parents[2] / "clients" / "python"

# The committed generated client against a fresh generation from the committed spec.
fresh = work / "fresh"
subprocess.run([sys.executable, str(package / "generate.py"), str(fresh)], check=True)
committed = package / "nuno" / "_generated"
stale = []
for path in sorted(fresh.rglob("*.py")):
    relative = path.relative_to(fresh)
    if not (committed / relative).exists() or not filecmp.cmp(path, committed / relative, shallow=False):
        stale.append(str(relative))
stale += [str(p.relative_to(committed)) for p in committed.rglob("*.py") if not (fresh / p.relative_to(committed)).exists()]

client = nuno.Client(base)
states = np.zeros((2, 11), dtype=np.float32)
states[:, 0] = 1.25
actions = np.array([[0.1, 0.2, 0.3], [0.0, 0.0, 0.0]], dtype=np.float32)
as_json = client.step("hopper-random", states, actions, particles=2, seed=3, binary=False)
as_binary = client.step("hopper-random", states, actions, particles=2, seed=3, binary=True)
rollout = client.rollout("hopper-random", states, 4, particles=3, seed=1)
errors = {}
for name, call in {
    "missing": lambda: client.step("no-such-model", states, actions),
    "narrow": lambda: client.step("hopper-random", states[:, :5], actions),
}.items():
    try:
        call()
        errors[name] = None
    except nuno.NunoError as e:
        errors[name] = {"status": e.status, "code": e.code, "message": e.message}

# The model as a Gymnasium environment: Gymnasium's own checker, a seeded
# episode that repeats, and a first step that is the server's step with the
# seeds Gymnasium's generator draws (recomputed here from its seeding).
import gymnasium  # noqa: E402
from gymnasium.utils.env_checker import check_env  # noqa: E402

from nuno.gym import ModelEnv  # noqa: E402

starts = np.stack([states[0], states[0] + 0.01])
env = ModelEnv(client, "hopper-random", start_states=starts, max_episode_steps=5, eta_budget=100.0)
check_env(env, skip_render_check=True)


def episode(seed):
    env = ModelEnv(client, "hopper-random", start_states=starts, max_episode_steps=5)
    first, _ = env.reset(seed=seed)
    steps = [env.step(np.array([0.1, -0.2, 0.3], dtype=np.float32)) for _ in range(3)]
    return first, steps


first, steps = episode(5)
again_first, again = episode(5)
rng, _ = gymnasium.utils.seeding.np_random(5)
start = starts[rng.integers(len(starts))]
expected = client.step("hopper-random", start[None], np.array([[0.1, -0.2, 0.3]], dtype=np.float32),
                       seed=int(rng.integers(2**63)), binary=False)
gym = {
    "action_box": [env.action_space.low.tolist(), env.action_space.high.tolist()],
    "repeats": bool(np.array_equal(first, again_first)
                    and all(np.array_equal(a[0], b[0]) and a[1] == b[1] for a, b in zip(steps, again))),
    "first_step_is_the_servers": bool(np.array_equal(first, start)
                                      and np.array_equal(steps[0][0], expected.next_states[0, 0])
                                      and steps[0][1] == float(expected.penalized_rewards[0, 0])
                                      and steps[0][4]["eta"] == float(expected.eta[0])),
    "truncated_at_limit": [s[3] for s in steps],
}

candidates = (np.arange(72) / 71.0 - 0.5).astype(np.float32).reshape(2, 3, 4, 3)
scores = client.score("hopper-random", states, candidates, particles=2, seed=4, cvar_alpha=0.5)
plan = client.plan("hopper-random", states[0], planner="cem", horizon=3, population=8, iterations=1)

(work / "result.json").write_text(json.dumps({
    "gym": gym,
    "score_mean_return": scores.mean_return.tolist(),
    "score_shape": list(scores.max_eta.shape),
    "plan_actions": np.asarray(plan.actions).shape,
    "plan_first_is_first": plan.first_action == plan.actions[0],
    "stale": stale,
    "models": [m.id for m in client.models()],
    "kind": str(client.model("hopper-random").kind),
    "step_json": {k: np.asarray(getattr(as_json, k)).tolist() for k in ("next_states", "eta", "terminals")},
    "step_binary_equal": all(
        np.array_equal(getattr(as_json, k), getattr(as_binary, k))
        for k in ("mean", "sigma", "h_eta", "eta", "next_states", "rewards", "penalized_rewards", "terminals")
    ),
    "rollout_shapes": [list(rollout.states.shape), list(rollout.actions.shape), list(rollout.eta.shape)],
    "rollout_length": rollout.length.tolist(),
    "act": client.act("hopper-random", states).tolist(),
    "errors": errors,
}))
