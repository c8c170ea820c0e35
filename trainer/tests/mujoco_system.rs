//! A user's system that MuJoCo simulates (`examples/cartpole`: a system file
//! with a `[mujoco]` table and its own MJCF) through the trainer on tiny
//! budgets, as docs/your-own-system.md's section 4 runs it: `dataset
//! generate --system` (checked against the file's own termination rule),
//! `fit-model`, `fit-policy` evaluating in the simulator, `evaluate` of the
//! random and the trained policy; the model folder carries the MJCF, so it
//! simulates with no file beside it.

mod common;

use std::path::{Path, PathBuf};

use common::{fails, ok, tiny_fit_policy};
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
    ok(&tiny_fit_policy("nuno", &model, &data, None, 20, &run, &[]));
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

/// `collect online-sac --system`: SAC trains online in the file's simulator,
/// its run records the system file (MJCF inlined, no built-in task), its
/// checkpoint policies name the system and evaluate in the run's copy of it,
/// a resumed run checks it is the same file, and `collect select` (D4RL's recipes are the built-in tasks') says why
/// it will not pick levels.
#[test]
fn online_sac_trains_in_a_system_files_simulator_and_resumes() {
    let tmp = tempfile::tempdir().unwrap();
    let path = |p: &Path| p.display().to_string();
    let run = tmp.path().join("online");
    let online = |system: &Path, steps: &str, extra: &[&str]| {
        let mut args = vec![
            "collect".to_string(),
            "online-sac".into(),
            "--system".into(),
            path(system),
            "--steps".into(),
            steps.into(),
            "--checkpoint-every".into(),
            "100".into(),
            "--start-steps".into(),
            "50".into(),
            "--eval-episodes".into(),
            "1".into(),
            "--batch-size".into(),
            "16".into(),
            "--hidden".into(),
            "16,16".into(),
            "--out".into(),
            path(&run),
        ];
        args.extend(extra.iter().map(|s| s.to_string()));
        args
    };
    let args = online(&system(), "200", &[]);
    ok(&args);
    let info: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("run.json")).unwrap()).unwrap();
    assert!(info.get("task").is_none(), "{info}");
    let recorded = info["system"].as_str().unwrap();
    assert!(
        recorded.contains("model_xml") && recorded.contains("<mujoco"),
        "the MJCF is inlined: {recorded}"
    );
    let policy: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(run.join("policies/step-00000200.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(policy["system"], "cartpole", "{policy}");
    assert!(policy.get("task").is_none(), "{policy}");

    let args = online(&system(), "300", &["--resume"]);
    let resumed = ok(&args);
    assert!(resumed.contains("resumed at step 200"), "{resumed}");
    assert!(run.join("policies/step-00000300.json").is_file());
    // A checkpoint's policy evaluates in the system its run recorded.
    let policies = path(&run.join("policies"));
    let report = ok(&[
        "evaluate",
        "--policy",
        &policies,
        "--policy-name",
        "step-00000300",
        "--episodes",
        "1",
        "--json",
    ]);
    let report: serde_json::Value = serde_json::from_str(&report).unwrap();
    assert_eq!(
        report["returns"].as_array().map(Vec::len),
        Some(1),
        "{report}"
    );

    // The same run with another system file: refused, nothing overwritten.
    let other = tmp.path().join("system.toml");
    let text = std::fs::read_to_string(system()).unwrap();
    std::fs::write(
        &other,
        text.replace(
            "cartpole.xml",
            &path(&system().with_file_name("cartpole.xml")),
        )
        .replace("name = \"cartpole\"", "name = \"cartpole-2\""),
    )
    .unwrap();
    let args = online(&other, "400", &["--resume"]);
    let err = fails(&args);
    assert!(err.contains("started with other settings"), "{err}");

    let err = fails(&[
        "collect".to_string(),
        "select".into(),
        "--run".into(),
        path(&run),
        "--out".into(),
        path(&tmp.path().join("behaviour")),
    ]);
    assert!(err.contains("built-in tasks, not for `cartpole`"), "{err}");
}
