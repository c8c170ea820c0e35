//! Gymnasium's swimmer, inverted pendulum and ant through the trainer on tiny
//! budgets: `dataset generate` makes their random datasets (checked against
//! each task's termination rule, written here from Gymnasium's source), and on
//! the ant (a free root, whose quaternion the drift learns alone) `fit-model`,
//! `fit-policy` without a preset, evaluating in the simulator, and `evaluate`
//! run to the end. Their simulators are held to Python Gymnasium in
//! `tests/gymnasium_parity.rs`.

mod common;

use std::path::Path;

use common::{ok, tiny_fit_policy};
use nuno::data::{Dataset, DatasetFormat, read_dataset};

fn generate(task: &str, transitions: usize, out: &Path) -> Dataset {
    ok(&[
        "dataset",
        "generate",
        "--task",
        task,
        "--kind",
        "random",
        "--transitions",
        &transitions.to_string(),
        "--seed",
        "0",
        "--out",
        out.to_str().unwrap(),
    ]);
    read_dataset(out, Some(DatasetFormat::D4rl)).unwrap()
}

#[test]
fn random_datasets_of_the_gymnasium_tasks_follow_their_rules() {
    let tmp = tempfile::tempdir().unwrap();
    // (task, observation and action widths, action limit, terminal(next observation))
    type Terminal = fn(&[f32]) -> bool;
    let tasks: [(&str, usize, usize, f32, Terminal); 3] = [
        // Swimmer-v4 never terminates.
        ("swimmer", 8, 2, 1.0, |_| false),
        // InvertedPendulum-v4: `not isfinite(ob).all() or abs(ob[1]) > 0.2`.
        ("invertedpendulum", 4, 1, 3.0, |s| s[1].abs() > 0.2),
        // Ant-v4: the torso's height qpos[2] (observation 0) outside [0.2, 1.0].
        ("ant", 27, 8, 1.0, |s| !(0.2..=1.0).contains(&s[0])),
    ];
    for (task, obs_dim, act_dim, limit, terminal) in tasks {
        let data = generate(task, 2000, &tmp.path().join(format!("{task}.hdf5")));
        assert_eq!(data.len(), 2000, "{task}");
        assert_eq!(data.observations.ncols(), obs_dim, "{task}");
        assert_eq!(data.actions.ncols(), act_dim, "{task}");
        assert!(data.actions.iter().all(|a| a.abs() <= limit), "{task}");
        for (i, next) in data.next_observations.rows().into_iter().enumerate() {
            let next = next.to_vec();
            assert_eq!(data.terminals[i], terminal(&next), "{task} row {i}");
        }
        let falls = data.terminals.iter().filter(|&&t| t).count();
        match task {
            // 1000-step episodes, cut by the time limit.
            "swimmer" => assert_eq!(data.timeouts.iter().filter(|&&t| t).count(), 2),
            // Random pushes tip the pole within a few steps (Gymnasium's own
            // random return is 6.0 a episode).
            "invertedpendulum" => assert!(falls > 100, "{falls} falls"),
            _ => {}
        }
    }
}

#[test]
fn the_ant_fits_trains_and_evaluates_in_its_simulator() {
    let tmp = tempfile::tempdir().unwrap();
    let path = |p: &Path| p.display().to_string();
    let data = tmp.path().join("ant.hdf5");
    generate("ant", 1500, &data);
    let model = tmp.path().join("model");
    ok(&[
        "fit-model",
        "--task",
        "ant",
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
    let metadata: serde_json::Value =
        serde_json::from_slice(&std::fs::read(model.join("model.json")).unwrap()).unwrap();
    // The height pairs with the root's z velocity (qvel[2], observation 13 + 2).
    assert_eq!(
        metadata["spec"]["split"]["position_velocity"],
        serde_json::json!([15])
    );

    let run = tmp.path().join("policy-run");
    let log = ok(&tiny_fit_policy("nuno", &model, &data, None, 20, &run, &[]));
    let metrics = std::fs::read_to_string(run.join("metrics.jsonl")).unwrap();
    let last: serde_json::Value = serde_json::from_str(metrics.lines().last().unwrap()).unwrap();
    // Evaluated in the simulator, not in the model: a normalised score exists.
    assert!(last["eval"]["normalized_score"].is_f64(), "{last}\n{log}");
    assert_ne!(last["eval"]["in_model"], serde_json::json!(true), "{last}");

    let report = ok(&["evaluate", "--policy", &path(&model), "--episodes", "2"]);
    assert!(report.contains("ant"), "{report}");
}
