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

# The batched variant: one server step per vector step, the same draws as the
# server's step of the batch with the seed Gymnasium's generator gives, and
# Gymnasium's NEXT_STEP autoreset after the episodes' limit.
from nuno.gym import ModelVectorEnv  # noqa: E402

venv = ModelVectorEnv(client, "hopper-random", 3, start_states=starts, max_episode_steps=2)
push = np.tile(np.array([0.1, -0.2, 0.3], dtype=np.float32), (3, 1))
v_first, _ = venv.reset(seed=7)
v_steps = [venv.step(push) for _ in range(3)]
rng, _ = gymnasium.utils.seeding.np_random(7)
v_start = starts[rng.integers(len(starts), size=3)]
v_expected = client.step("hopper-random", v_start, push, seed=int(rng.integers(2**63)))
second = client.step("hopper-random", v_expected.next_states[:, 0], push, seed=int(rng.integers(2**63)))
rng.integers(2**63)  # the third step's seed, whose rows the autoreset replaces
v_restart = starts[rng.integers(len(starts), size=3)]
vector = {
    "spaces": [list(venv.observation_space.shape), list(venv.action_space.shape)],
    "first_step_is_the_servers": bool(
        np.array_equal(v_first, v_start)
        and np.array_equal(v_steps[0][0], v_expected.next_states[:, 0])
        and np.array_equal(v_steps[0][1], v_expected.penalized_rewards[:, 0].astype(np.float64))
        and np.array_equal(v_steps[0][4]["eta"], v_expected.eta.astype(np.float64))
        and np.array_equal(v_steps[1][0], second.next_states[:, 0])),
    "ended_at_limit": (v_steps[1][2] | v_steps[1][3]).tolist(),
    "autoreset": bool(np.array_equal(v_steps[2][0], v_restart) and not v_steps[2][1].any()
                      and not (v_steps[2][2] | v_steps[2][3]).any()),
}

candidates = (np.arange(72) / 71.0 - 0.5).astype(np.float32).reshape(2, 3, 4, 3)
scores = client.score("hopper-random", states, candidates, particles=2, seed=4, cvar_alpha=0.5)
plan = client.plan("hopper-random", states[0], planner="cem", horizon=3, population=8, iterations=1)

(work / "result.json").write_text(json.dumps({
    "gym": gym,
    "vector": vector,
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
