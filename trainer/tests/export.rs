//! `nuno-trainer export --format onnx` on the shipped model: both graphs and
//! the contract written where asked, their inputs and outputs printed; bad
//! flags and a folder that holds no model named. (ONNX Runtime's agreement
//! with the server is `tests/export.rs`'s.)

mod common;

use std::path::Path;

use common::{fails, ok};

#[test]
fn export_writes_the_onnx_files_and_their_contract() {
    let tmp = tempfile::tempdir().unwrap();
    let model = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/hopper-random");
    let out = tmp.path().join("onnx");
    let (model_arg, out_arg) = (model.to_str().unwrap(), out.to_str().unwrap());
    let printed = ok(&[
        "export", "--model", model_arg, "--format", "onnx", "--out", out_arg,
    ]);
    assert!(
        printed.contains(
            "(observation, action, noise) → (mean, sigma, h_eta, next_state, eta, reward, terminal)"
        ),
        "{printed}"
    );
    assert!(
        printed.contains("(observation, noise) → (deterministic_action, sampled_action, log_prob)"),
        "{printed}"
    );
    let contract: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("contract.json")).unwrap()).unwrap();
    assert_eq!(contract["opset"], 17);
    assert_eq!(
        contract["model"]["inputs"][0]["shape"],
        serde_json::json!(["batch", 11])
    );
    assert_eq!(contract["policy"]["outputs"][2]["name"], "log_prob");
    for file in ["model.onnx", "policy.onnx"] {
        assert!(out.join(file).metadata().unwrap().len() > 1000, "{file}");
    }

    let err = fails(&["export", "--model", model_arg, "--format", "tflite"]);
    assert!(err.contains("tflite"), "{err}");
    let empty = tmp.path().to_str().unwrap();
    let err = fails(&[
        "export", "--model", empty, "--format", "onnx", "--out", out_arg,
    ]);
    assert!(err.contains(empty), "{err}");
}
