//! A user's system that MuJoCo simulates (`examples/cartpole`: a system file
//! with a `[mujoco]` table and its own MJCF) through the trainer on tiny
//! budgets, as docs/your-own-system.md's section 4 runs it: `dataset
//! generate --system` (checked against the file's own termination rule),
//! `fit-model`, `fit-policy` evaluating in the simulator, `evaluate` of the
//! random and the trained policy; the model folder carries the MJCF, so it
//! simulates with no file beside it.

mod common;

use std::path::{Path, PathBuf};

use common::{fails, ok};
use nuno::artifact::ModelFolder;
use nuno::data::{DatasetFormat, read_dataset};

fn system() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/cartpole/system.toml")
}

#[test]
fn the_cartpole_generates_fits_trains_and_evaluates_in_its_simulator() {
    let tmp = tempfile::tempdir().unwrap();
    let path = |p: &Path| p.display().to_string();
    let system = path(&system());
    let data = tmp.path().join("cartpole.hdf5");
    ok(&[
        "dataset",
        "generate",
        "--system",
        &system,
        "--kind",
        "random",
        "--transitions",
        "1500",
        "--seed",
        "0",
        "--out",
        &path(&data),
    ]);
    let dataset = read_dataset(&data, Some(DatasetFormat::D4rl)).unwrap();
    assert_eq!(
        (dataset.observations.ncols(), dataset.actions.ncols()),
        (4, 1)
    );
    assert!(dataset.actions.iter().all(|a| a.abs() <= 1.0));
    // The pole past ±0.2 rad ends an episode, and random pushes tip it often.
    for (i, next) in dataset.next_observations.rows().into_iter().enumerate() {
        assert_eq!(dataset.terminals[i], next[1].abs() > 0.2, "row {i}");
    }
    assert!(dataset.terminals.iter().filter(|&&t| t).count() > 10);

    let model = tmp.path().join("cartpole");
    ok(&[
        "fit-model",
        "--system",
        &system,
        "--dataset",
        &path(&data),
        "--out",
        &path(&model),
        "--drift-hidden",
        "16,16",
        "--max-steps",
        "20",
        "--eval-every",
        "10",
    ]);
    // The folder's copy of the system simulates without examples/cartpole beside it.
    let folder = ModelFolder::load(&model, &burn::tensor::Device::flex()).unwrap();
    let recorded = folder.system().unwrap().expect("a system is recorded");
    assert!(recorded.simulator().is_some(), "{}", recorded.name());

    let run = tmp.path().join("policy-run");
    ok(&[
        "fit-policy",
        "--model",
        &path(&model),
        "--dataset",
        &path(&data),
        "--horizon",
        "5",
        "--cvar-alpha",
        "1",
        "--penalty",
        "1",
        "--steps",
        "20",
        "--steps-per-epoch",
        "10",
        "--rollout-freq",
        "10",
        "--rollout-batch",
        "32",
        "--batch-size",
        "32",
        "--hidden",
        "16,16",
        "--eval-episodes",
        "1",
        "--out",
        &path(&run),
    ]);
    let metrics = std::fs::read_to_string(run.join("metrics.jsonl")).unwrap();
    let last: serde_json::Value = serde_json::from_str(metrics.lines().last().unwrap()).unwrap();
    // Evaluated in the simulator: a normalised score (return / 10 by the file's references).
    let eval = &last["eval"];
    assert_ne!(eval["in_model"], serde_json::json!(true), "{last}");
    let (ret, score) = (
        eval["mean_return"].as_f64(),
        eval["normalized_score"].as_f64(),
    );
    assert_eq!(score, ret.map(|r| r / 10.0), "{last}");

    let random = ok(&[
        "evaluate",
        "--policy",
        "random",
        "--system",
        &system,
        "--episodes",
        "2",
        "--json",
    ]);
    let report: serde_json::Value = serde_json::from_str(&random).unwrap();
    assert_eq!(
        report["returns"].as_array().map(Vec::len),
        Some(2),
        "{report}"
    );
    // The policy sits in the model folder, whose copy of the system simulates it.
    let trained = ok(&["evaluate", "--policy", &path(&model), "--episodes", "2"]);
    assert!(trained.contains("cartpole"), "{trained}");
    let given = ok(&[
        "evaluate",
        "--policy",
        &path(&model),
        "--system",
        &system,
        "--episodes",
        "2",
    ]);
    assert_eq!(
        given, trained,
        "the file given is the one the folder recorded"
    );
    // Saved elsewhere, the policy records its system by name only: the file is needed.
    let policies = tmp.path().join("policies");
    std::fs::create_dir(&policies).unwrap();
    for file in ["policy.json", "policy.safetensors"] {
        std::fs::copy(model.join(file), policies.join(file)).unwrap();
    }
    let message = fails(&["evaluate", "--policy", &path(&policies), "--episodes", "2"]);
    assert!(message.contains("give the file (--system)"), "{message}");
}
