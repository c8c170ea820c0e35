"""The served step over the Open Inference Protocol's two transports, and the
exported step in ONNX Runtime against nuno's fused kernel (issue 36, item 6).

1. REST with the binary tensor extension (tritonclient.http, binary inputs and
   outputs) against gRPC with raw contents (tritonclient.grpc), one
   nuno-server (release) on loopback serving models/hopper-random: per batch
   (1, 256), the latency of one client's sequential calls (p50, p99) and the
   throughput of CLIENTS concurrent clients for SECONDS.
2. models/hopper-random exported with `nuno-trainer export --format onnx`, its
   step run in process by ONNX Runtime (CPU, every core) at batch 1, 256 and
   4096; nuno's fused step at the same batches comes from `cargo bench --bench
   infer` run by the caller in the same session (the EM step table).

Usage (repository root, release build, `make venv` plus `pip install "tritonclient[http]==2.73.0"`):
  .venv/bin/python benches/oip_transports.py [--seconds 10] [--clients 4]"""

import argparse
import os
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import onnxruntime as ort
import tritonclient.grpc as grpc_client
import tritonclient.http as http_client

MODEL = "hopper-random"
TARGET = Path(os.environ.get("CARGO_TARGET_DIR", "target")) / "release"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def rows(batch: int, rng: np.random.Generator):
    states = np.zeros((batch, 11), np.float32)
    states[:, 0] = 1.25
    states[:, 1:] = rng.normal(0, 0.05, (batch, 10))
    actions = rng.uniform(-1, 1, (batch, 3)).astype(np.float32)
    return states, actions


class Transport:
    """One client library's `infer` of the step, binary both ways."""

    def __init__(self, name, module, url, states, actions):
        self.name, self.module = name, module
        self.client = module.InferenceServerClient(url)
        self.inputs = []
        for tensor, values in (("states", states), ("actions", actions)):
            t = module.InferInput(tensor, list(values.shape), "FP32")
            if module is http_client:
                t.set_data_from_numpy(values, binary_data=True)
            else:
                t.set_data_from_numpy(values)
            self.inputs.append(t)
        kw = {"binary_data": True} if module is http_client else {}
        self.outputs = [module.InferRequestedOutput(n, **kw) for n in ("next_states", "eta", "rewards", "terminals")]

    def call(self):
        result = self.client.infer(MODEL, self.inputs, outputs=self.outputs)
        return result.as_numpy("next_states")


def latency(transport: Transport, calls: int):
    transport.call()  # connection and first-call costs out of the figures
    times = []
    for _ in range(calls):
        start = time.perf_counter()
        transport.call()
        times.append(time.perf_counter() - start)
    return np.percentile(times, 50) * 1e3, np.percentile(times, 99) * 1e3


def throughput(make, clients: int, seconds: float) -> float:
    counts = [0] * clients
    stop = time.perf_counter() + seconds

    def work(i):
        transport = make()
        transport.call()
        while time.perf_counter() < stop:
            transport.call()
            counts[i] += 1

    threads = [threading.Thread(target=work, args=(i,)) for i in range(clients)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    return sum(counts) / seconds


def transports(args):
    http_port, grpc_port = free_port(), free_port()
    server = subprocess.Popen(
        [str(TARGET / "nuno-server"), "--models", "models", "--addr", f"127.0.0.1:{http_port}",
         "--grpc-addr", f"127.0.0.1:{grpc_port}", "--batch-delay-us", "0"],
        stderr=subprocess.DEVNULL,
    )
    try:
        probe = http_client.InferenceServerClient(f"127.0.0.1:{http_port}")
        for _ in range(200):
            try:
                if probe.is_server_ready():
                    break
            except Exception:
                time.sleep(0.1)
        rng = np.random.default_rng(0)
        print("| transport | batch | p50 ms | p99 ms | calls/s, 1 client | calls/s, "
              f"{args.clients} clients | transitions/s, {args.clients} clients |")
        print("|---|---|---|---|---|---|---|")
        for batch in (1, 256):
            states, actions = rows(batch, rng)
            for name, module, port in (("REST, binary extension", http_client, http_port),
                                       ("gRPC, raw contents", grpc_client, grpc_port)):
                make = lambda: Transport(name, module, f"127.0.0.1:{port}", states, actions)  # noqa: E731
                p50, p99 = latency(make(), args.calls)
                alone = throughput(make, 1, args.seconds)
                many = throughput(make, args.clients, args.seconds)
                print(f"| {name} | {batch} | {p50:.2f} | {p99:.2f} | {alone:.0f} | {many:.0f} | {many * batch:.0f} |")
    finally:
        server.terminate()
        server.wait()


def onnx_runtime(args):
    with tempfile.TemporaryDirectory() as out:
        subprocess.run([str(TARGET / "nuno-trainer"), "export", "--model", f"models/{MODEL}",
                        "--format", "onnx", "--out", out], check=True, stdout=subprocess.DEVNULL)
        options = ort.SessionOptions()
        options.intra_op_num_threads = os.cpu_count()
        session = ort.InferenceSession(f"{out}/model.onnx", options, providers=["CPUExecutionProvider"])
        rng = np.random.default_rng(0)
        print(f"\n| ONNX Runtime {ort.__version__}, in process ({os.cpu_count()} threads) | batch | "
              "transitions/s | µs per step |")
        print("|---|---|---|---|")
        for batch in (1, 256, 4096):
            states, actions = rows(batch, rng)
            feed = {"observation": states, "action": actions,
                    "noise": rng.standard_normal((batch, 11)).astype(np.float32)}
            session.run(None, feed)
            calls, start = 0, time.perf_counter()
            while time.perf_counter() - start < args.seconds / 2:
                session.run(None, feed)
                calls += 1
            seconds = (time.perf_counter() - start) / calls
            print(f"| model.onnx step | {batch} | {batch / seconds:.0f} | {seconds * 1e6:.1f} |")


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--clients", type=int, default=4)
    parser.add_argument("--calls", type=int, default=500)
    args = parser.parse_args()
    transports(args)
    onnx_runtime(args)


if __name__ == "__main__":
    sys.exit(main())
