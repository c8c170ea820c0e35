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

(work / "result.json").write_text(json.dumps({
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
