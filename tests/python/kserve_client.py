"""KServe's own Python client (kserve from PyPI, InferenceRESTClient, protocol
v2) against a running nuno-server: health, readiness, and `infer` with the
binary tensor extension off and on (inputs and outputs). Writes what it got to
result.json for the Rust test to compare with `/v1/models/{id}/step`.

Usage: kserve_client.py BASE_URL MODEL STATES_JSON ACTIONS_JSON
"""

import asyncio
import json
import sys

import numpy as np
from kserve import InferenceRESTClient, InferInput, InferRequest, RESTConfig
from kserve.protocol.infer_type import RequestedOutput

OUTPUTS = ["next_states", "eta", "penalized_rewards", "terminals"]


async def main(base, model, states, actions):
    client = InferenceRESTClient(RESTConfig(protocol="v2", timeout=60))
    result = {
        "live": await client.is_server_live(base),
        "ready": await client.is_server_ready(base),
        "model_ready": await client.is_model_ready(base, model),
    }
    for binary in (False, True):
        inputs = []
        for name, values in (("states", states), ("actions", actions)):
            tensor = InferInput(name, list(values.shape), "FP32")
            tensor.set_data_from_numpy(values, binary_data=binary)
            inputs.append(tensor)
        request = InferRequest(
            model_name=model,
            infer_inputs=inputs,
            parameters={"seed": 3, "penalty": 0.5},
            request_outputs=[RequestedOutput(n, {"binary_data": binary}) for n in OUTPUTS],
        )
        headers = {}
        response = await client.infer(base, request, model_name=model, response_headers=headers)
        result["binary" if binary else "json"] = {
            "content_type": headers.get("content-type"),
            "outputs": {o.name: o.as_numpy().astype(float).tolist() for o in response.outputs},
        }
    await client.close()
    with open("result.json", "w") as f:
        json.dump(result, f)


if __name__ == "__main__":
    base, model = sys.argv[1], sys.argv[2]
    states = np.array(json.loads(sys.argv[3]), dtype=np.float32)
    actions = np.array(json.loads(sys.argv[4]), dtype=np.float32)
    asyncio.run(main(base, model, states, actions))
