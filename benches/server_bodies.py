"""Request bodies for the server load benchmark: hopper step batches as JSON and
as safetensors (binary), a rollout of 4096 starts x 10 steps with the policy, and
plan calls."""
import json
import sys
from pathlib import Path

import numpy as np
from safetensors.numpy import save

out = Path(sys.argv[1])
out.mkdir(parents=True, exist_ok=True)
rng = np.random.default_rng(0)


def states(n):
    s = rng.normal(0.0, 0.1, size=(n, 11)).astype(np.float32)
    s[:, 0] += 1.25
    return s


for n in (1, 256, 4096):
    s, a = states(n), rng.uniform(-1, 1, size=(n, 3)).astype(np.float32)
    (out / f"step-{n}.json").write_text(json.dumps({"states": s.tolist(), "actions": a.tolist(), "seed": 0}))
    (out / f"step-{n}.bin").write_bytes(save({"states": s, "actions": a}, metadata={"seed": "0"}))
(out / "rollout-4096.json").write_text(
    json.dumps({"states": states(4096).tolist(), "horizon": 10, "alpha": 0.99, "seed": 0})
)

# Planning (issue 33): plan calls at PETS' hopper sizes (CEM) and iCEM's (iCEM)
# (planning::PlanBudget); the score bodies come from `cargo bench --bench score`.
start = states(1)
for name, (planner, h, n, iters, p) in {
    "pets": ("cem", 30, 350, 5, 20), "icem": ("icem", 10, 200, 5, 20)
}.items():
    (out / f"plan-{name}.json").write_text(json.dumps(
        {"state": start[0].tolist(), "planner": planner, "horizon": h, "population": n,
         "iterations": iters, "particles": p, "seed": 0}))
