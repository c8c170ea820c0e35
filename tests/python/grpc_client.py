"""Triton's gRPC client (tritonclient[grpc] from PyPI) against nuno-server's
Open Inference Protocol service: health, metadata, ModelInfer with raw and
with typed contents (the values `/v1/.../step` answered for the same seed, in
expected.json), the token as metadata, and bad requests answered with the
matching status code and a message naming what was wrong.

Usage: grpc_client.py HOST:PORT MODEL TOKEN (in the folder holding expected.json)"""

import json
import sys

import grpc
import numpy as np
import tritonclient.grpc as triton
from tritonclient.grpc import service_pb2, service_pb2_grpc
from tritonclient.utils import InferenceServerException

OUTPUTS = ["next_states", "eta", "penalized_rewards", "terminals"]


def tensor(name, values, datatype="FP32"):
    t = triton.InferInput(name, list(values.shape), datatype)
    t.set_data_from_numpy(values)
    return t


def refused(call, status, *named):
    """`call` fails with `status`, its message naming each of `named`."""
    try:
        call()
    except InferenceServerException as e:
        assert e.status() == status, f"{status} expected, got {e.status()}: {e.message()}"
        for name in named:
            assert name in e.message(), f"{name!r} not in {e.message()!r}"
        return
    raise AssertionError(f"accepted, {status} expected")


def check_infer(client, model, expected, headers):
    states = np.array(expected["states"], np.float32)
    actions = np.array(expected["actions"], np.float32)
    wanted = [triton.InferRequestedOutput(name) for name in OUTPUTS]
    # The seed as int64, the penalty as a string: KServe's InferParameter has no double.
    result = client.infer(
        model,
        [tensor("states", states), tensor("actions", actions)],
        outputs=wanted,
        headers=headers,
        parameters={"seed": 3, "penalty": "0.5"},
    )
    for name in OUTPUTS:
        got, want = result.as_numpy(name), np.array(expected[name])
        assert got.shape == want.shape, f"{name}: shape {got.shape}, expected {want.shape}"
        assert np.array_equal(got, want.astype(got.dtype)), f"{name}: {got} != {want}"
    assert result.get_response().parameters["clipped_rows"].int64_param == 0
    return states, actions


def check_typed_contents(address, model, token, states, expected):
    """fp32_contents instead of raw_input_contents: the same answer."""
    request = service_pb2.ModelInferRequest(model_name=model)
    request.parameters["seed"].int64_param = 3
    request.parameters["penalty"].string_param = "0.5"
    for name, values in (("states", states), ("actions", np.array(expected["actions"], np.float32))):
        t = request.inputs.add(name=name, datatype="FP32", shape=list(values.shape))
        t.contents.fp32_contents.extend(values.ravel().tolist())
    request.outputs.add(name="next_states")
    with grpc.insecure_channel(address) as channel:
        stub = service_pb2_grpc.GRPCInferenceServiceStub(channel)
        response = stub.ModelInfer(request, metadata=[("authorization", f"Bearer {token}")])
    (output,) = response.outputs
    got = np.frombuffer(response.raw_output_contents[0], np.float32).reshape(list(output.shape))
    assert np.array_equal(got, np.array(expected["next_states"], np.float32)), "typed contents"


def check_refusals(client, model, states, actions, headers):
    good = [tensor("actions", actions)]
    refused(lambda: client.infer(model, [tensor("states", states)] + good), "StatusCode.UNAUTHENTICATED", "token")
    refused(lambda: client.infer("no-such-model", [tensor("states", states)] + good, headers=headers),
            "StatusCode.NOT_FOUND", "no-such-model")
    refused(lambda: client.infer(model, [tensor("states", states.astype(np.float64), "FP64")] + good, headers=headers),
            "StatusCode.INVALID_ARGUMENT", "states", "FP32")
    refused(lambda: client.infer(model, [tensor("states", states[:, :5])] + good, headers=headers),
            "StatusCode.INVALID_ARGUMENT", "states")
    refused(lambda: client.infer(model, good, headers=headers), "StatusCode.INVALID_ARGUMENT", "states", "missing")
    over = np.repeat(states, 20, axis=0)
    refused(lambda: client.infer(model, [tensor("states", over), tensor("actions", np.repeat(actions, 20, axis=0))],
                                 headers=headers),
            "StatusCode.RESOURCE_EXHAUSTED", "batch")
    refused(lambda: client.infer(model, [tensor("states", states)] + good, headers=headers,
                                 outputs=[triton.InferRequestedOutput("velocity")]),
            "StatusCode.INVALID_ARGUMENT", "velocity")
    # A double travels in Triton's field, which the protocol's InferParameter lacks.
    refused(lambda: client.infer(model, [tensor("states", states)] + good, headers=headers,
                                 parameters={"penalty": 0.5}),
            "StatusCode.INVALID_ARGUMENT", "penalty")


def main(address, model, token):
    expected = json.load(open("expected.json"))
    client = triton.InferenceServerClient(address)
    headers = {"authorization": f"Bearer {token}"}
    assert client.is_server_live() and client.is_server_ready()
    assert client.is_model_ready(model, headers=headers)
    refused(lambda: client.is_model_ready("no-such-model", headers=headers), "StatusCode.NOT_FOUND", "no-such-model")
    assert client.get_server_metadata(headers=headers).name == "nuno"
    metadata = client.get_model_metadata(model, headers=headers)
    assert [(t.name, t.datatype, list(t.shape)) for t in metadata.inputs] == [
        ("states", "FP32", [-1, 11]),
        ("actions", "FP32", [-1, 3]),
    ], metadata.inputs
    assert "terminals" in [t.name for t in metadata.outputs]
    states, actions = check_infer(client, model, expected, headers)
    check_typed_contents(address, model, token, states, expected)
    check_refusals(client, model, states, actions, headers)
    print("gRPC: health, metadata, raw and typed infer, refusals: ok")


if __name__ == "__main__":
    main(*sys.argv[1:4])
