"""The server against its own spec: schemathesis `--checks all` (every
phase: examples, coverage, fuzzing, stateful) on `<base>/openapi.json`, the
spec the running server serves with its limits. Exits non-zero on any
failure; contract_hooks.py says which two things are set aside and why.

Usage: contract.py BASE_URL MODEL_ID MAX_EXAMPLES

Generation is deterministic (the same cases on every machine and run).
"""

import json
import os
import subprocess
import sys
import tempfile
import urllib.request
from pathlib import Path

base, model, max_examples = sys.argv[1:4]
here = Path(__file__).resolve().parent
# Path `id`s and evaluate's `model` name the loaded model: random names would
# only ever meet 404 (tests/server.rs covers unknown models).
config = Path(tempfile.mkdtemp()) / "schemathesis.toml"
config.write_text(f'[parameters]\n"path.id" = "{model}"\n"body.model" = "{model}"\n')
schemathesis = Path(sys.executable).with_name("schemathesis")
with urllib.request.urlopen(f"{base}/v1/models/{model}") as answer:
    detail = json.load(answer)
env = dict(
    os.environ,
    SCHEMATHESIS_HOOKS="contract_hooks",
    PYTHONPATH=str(here),
    NUNO_OBS_DIM=str(detail["obs_dim"]),
    NUNO_ACT_DIM=str(detail["act_dim"]),
)
run = subprocess.run(
    [
        str(schemathesis), "--config-file", str(config), "run", f"{base}/openapi.json",
        "--checks", "all",
        "--max-examples", max_examples,
        "--generation-deterministic",
        "--no-color",
    ],
    env=env,
    cwd=os.getcwd(),
    capture_output=True,
    text=True,
)
print(run.stdout[-20000:])
if run.returncode != 0:
    print(run.stderr[-5000:], file=sys.stderr)
    print(run.stdout[-20000:], file=sys.stderr)
    sys.exit(f"schemathesis found failures (exit {run.returncode})")
