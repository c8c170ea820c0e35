"""Generates a Python client from the committed OpenAPI spec with
openapi-python-client (from PyPI) and calls a running nuno-server with it.

usage: openapi_client.py SPEC BASE_URL  (run in a scratch directory; writes result.json)
"""
import json
import subprocess
import sys
from pathlib import Path

spec, base = sys.argv[1], sys.argv[2]
work = Path.cwd()
config = work / "config.yml"
config.write_text("post_hooks: []\n")
generator = Path(sys.executable).parent / "openapi-python-client"
subprocess.run(
    [str(generator), "generate", "--path", spec, "--meta", "none",
     "--output-path", str(work / "nuno_client"), "--config", str(config)],
    check=True, capture_output=True,
)
sys.path.insert(0, str(work))

# openapi-python-client 0.29.1 annotates multi-content bodies (step: JSON or
# safetensors) with `Unset` without importing it; provide the name it means.
import builtins  # noqa: E402

from nuno_client.types import Unset  # noqa: E402

builtins.Unset = Unset

from nuno_client import Client  # noqa: E402
from nuno_client.api.models import act, list_models, step  # noqa: E402
from nuno_client.models import ActRequest, StepRequest  # noqa: E402

client = Client(base_url=base, raise_on_unexpected_status=True)
models = list_models.sync(client=client)
start = [1.25] + [0.0] * 10
stepped = step.sync(
    "hopper-random",
    client=client,
    body=StepRequest(states=[start, start], actions=[[0.1, 0.2, 0.3], [0.0, 0.0, 0.0]], particles=2, seed=3),
)
actions = act.sync("hopper-random", client=client, body=ActRequest(states=[start]))
missing = step.sync_detailed("no-such-model", client=client, body=StepRequest(states=[start], actions=[[0, 0, 0]]))
(work / "result.json").write_text(json.dumps({
    "models": [m.id for m in models.models],
    "eta": stepped.eta,
    "next_states": stepped.next_states,
    "actions": actions.actions,
    "missing_status": int(missing.status_code),
    "missing_code": missing.parsed.error.code,
}))
