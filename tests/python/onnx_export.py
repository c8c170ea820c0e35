"""Runs `nuno-trainer export`'s ONNX files with ONNX Runtime and compares them
with what nuno's own code computed on the same inputs and noise
(tests/export.rs writes both into each model's folder).

Usage: onnx_export.py ROOT, ROOT holding one folder per exported model
(model.onnx, policy.onnx, contract.json, cases.safetensors)."""

import json
import sys
from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
from safetensors.numpy import load_file

# The tolerance: |onnx − nuno| ≤ 1e-5·(|nuno| + RMS of the output), the
# RMS keeping entries that happen to be near zero on their output's scale.
TOLERANCE = 1e-5


def session(path: Path) -> ort.InferenceSession:
    onnx.checker.check_model(onnx.load(str(path)), full_check=True)
    return ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])


def check_contract(graph: dict, sess: ort.InferenceSession, what: str) -> None:
    """contract.json names the session's own inputs and outputs, shapes included."""
    for side, actual in (("inputs", sess.get_inputs()), ("outputs", sess.get_outputs())):
        named = [(t["name"], t["shape"]) for t in graph[side]]
        found = [(t.name, list(t.shape)) for t in actual]
        assert named == found, f"{what} {side}: contract {named}, graph {found}"


def compare(what: str, got: np.ndarray, want: np.ndarray) -> float:
    assert got.shape == want.shape, f"{what}: shape {got.shape}, expected {want.shape}"
    if want.dtype == np.bool_ or got.dtype == np.bool_:
        bad = np.flatnonzero(got.astype(bool) != want.astype(bool))
        assert bad.size == 0, f"{what}: differs at {bad[:10]} (onnx {got.ravel()[bad[:10]]})"
        return 0.0
    got, want = got.astype(np.float64), want.astype(np.float64)
    rms = np.sqrt(np.mean(want**2)) if want.size else 0.0
    relative = np.abs(got - want) / (np.abs(want) + rms)
    worst = float(relative.max())
    at = int(relative.argmax())
    assert worst <= TOLERANCE, (
        f"{what}[{at}]: onnx {got.ravel()[at]}, nuno {want.ravel()[at]} (relative {worst:.2e})"
    )
    return worst


def check_model(folder: Path) -> np.ndarray:
    """Compares every case of `folder`; returns the terminal flags nuno computed."""
    contract = json.loads((folder / "contract.json").read_text())
    assert contract["opset"] == 17, contract["opset"]
    model = session(folder / contract["model"]["file"])
    policy = session(folder / contract["policy"]["file"])
    check_contract(contract["model"], model, f"{folder.name} model")
    check_contract(contract["policy"], policy, f"{folder.name} policy")
    cases = load_file(str(folder / "cases.safetensors"))
    batches = sorted({int(name.split("/")[0]) for name in cases})
    worst, terminals = {}, []
    for batch in batches:
        case = {name.split("/", 1)[1]: v for name, v in cases.items() if name.startswith(f"{batch}/")}
        inputs = {k: case[f"in/{k}"] for k in ("observation", "action", "noise")}
        step = dict(zip([o.name for o in model.get_outputs()], model.run(None, inputs)))
        acted = policy.run(None, {"observation": case["in/observation"], "noise": case["in/policy_noise"]})
        acted = dict(zip([o.name for o in policy.get_outputs()], acted))
        for name, got in list(step.items()) + list(acted.items()):
            error = compare(f"{folder.name} batch {batch} {name}", got, case[name])
            worst[name] = max(worst.get(name, 0.0), error)
        terminals.append(case["terminal"])
    summary = ", ".join(f"{k} {v:.1e}" for k, v in worst.items())
    print(f"{folder.name}: batches {batches}; worst relative difference: {summary}")
    return np.concatenate(terminals)


def main() -> None:
    folders = sorted(p for p in Path(sys.argv[1]).iterdir() if p.is_dir())
    assert folders, f"no exported models under {sys.argv[1]}"
    terminals = np.concatenate([check_model(folder) for folder in folders])
    # The termination rules were compared on both sides of their boundaries.
    assert 0 < terminals.sum() < terminals.size, f"{terminals.sum()} of {terminals.size} terminal"


if __name__ == "__main__":
    main()
