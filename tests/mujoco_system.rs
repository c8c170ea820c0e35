//! A system file with a `[mujoco]` table simulates as a built-in task does:
//! hopper written as a user's file (its table and MJCF copied next to it)
//! steps bit for bit as the built-in hopper, which `gymnasium_parity.rs`
//! holds to Python Gymnasium; what the file leaves out (dt, the action box,
//! the split) comes from the model, and what it gives that disagrees with
//! the model is refused naming the key; an artifact's copy of the file reads
//! again with no MJCF file beside it.

use std::path::{Path, PathBuf};

use nuno::envs::{MujocoTask, SystemSpec, TaskConfig, TaskName};

const HOPPER_XML: &str = include_str!(concat!(env!("NUNO_MJCF_DIR"), "/hopper.xml"));
const HOPPER_TABLE: &str = include_str!("../src/envs/tasks/hopper.toml");

/// Hopper's observations by name (qpos[1..6], qvel[0..6]) and actions.
const HOPPER_NAMES: &str = r#"
name = "my-hopper"
observations = ["z", "pitch", "thigh", "leg", "foot",
                "x_dot", "z_dot", "pitch_dot", "thigh_dot", "leg_dot", "foot_dot"]
actions = ["thigh_torque", "leg_torque", "foot_torque"]

[reward]
expression = "next_x_dot + 1.0 - 0.001 * (thigh_torque^2 + leg_torque^2 + foot_torque^2)"
"#;

/// `header` plus hopper's own `[mujoco]` table, written with hopper.xml into `dir`.
fn hopper_file(dir: &Path, header: &str) -> PathBuf {
    std::fs::write(dir.join("hopper.xml"), HOPPER_XML).unwrap();
    let file = dir.join("my-hopper.toml");
    std::fs::write(&file, format!("{header}\n{HOPPER_TABLE}")).unwrap();
    file
}

/// 60 steps of a fixed action pattern from reset seed 3: every observation,
/// reward and end flag.
fn trajectory(task: &TaskConfig) -> Vec<(Vec<f64>, f64, bool, bool)> {
    let mut sim = MujocoTask::new(task).unwrap();
    let first = sim.reset(Some(3));
    let mut out = vec![(first, 0.0, false, false)];
    for t in 0..60 {
        let action: Vec<f64> = (0..3).map(|j| ((t * 3 + j) as f64 * 0.7).sin()).collect();
        let step = sim.step(&action).unwrap();
        out.push((
            step.observation,
            step.reward,
            step.terminated,
            step.truncated,
        ));
    }
    out
}

#[test]
fn a_file_with_hoppers_table_steps_as_the_built_in_hopper() {
    let dir = tempfile::tempdir().unwrap();
    let spec = SystemSpec::read(&hopper_file(dir.path(), HOPPER_NAMES)).unwrap();
    let built_in = TaskConfig::d4rl(TaskName::Hopper);
    let own = spec.simulation.clone().expect("a [mujoco] table simulates");
    assert_eq!(own.task.name(), "my-hopper");
    assert_eq!(trajectory(&own), trajectory(&built_in));

    // Left out of the file, taken from the model: 0.002 s × 4 frames, the
    // motors' ±1 ranges, the joints' pairs.
    let probe = MujocoTask::new(&built_in).unwrap();
    assert_eq!(spec.dt, probe.dt());
    assert_eq!(spec.dt, 0.008);
    assert_eq!(
        (spec.action_low.clone(), spec.action_high.clone()),
        probe.action_bounds()
    );
    assert_eq!(spec.split, probe.state_split());
}

#[test]
fn an_artifacts_copy_reads_again_without_the_mjcf_file() {
    let dir = tempfile::tempdir().unwrap();
    let spec = SystemSpec::read(&hopper_file(dir.path(), HOPPER_NAMES)).unwrap();
    assert!(spec.source.contains("model_xml"), "{}", spec.source);
    assert!(
        !spec.source.contains("model = \"hopper.xml\""),
        "{}",
        spec.source
    );
    // What a model.json records, read where no hopper.xml is.
    let again = SystemSpec::parse(&spec.source, Path::new("/elsewhere/model.json")).unwrap();
    assert_eq!(
        again.source, spec.source,
        "reading it again changes nothing"
    );
    assert_eq!(
        trajectory(&again.simulation.unwrap()),
        trajectory(&TaskConfig::d4rl(TaskName::Hopper))
    );
}

#[test]
fn what_disagrees_with_the_model_is_refused_naming_the_key() {
    let dir = tempfile::tempdir().unwrap();
    let with = |from: &str, to: &str| {
        assert!(HOPPER_NAMES.contains(from), "{from}");
        HOPPER_NAMES.replacen(from, to, 1)
    };
    let cases = [
        (
            with(r#""foot_dot"]"#, r#""foot_dot", "extra"]"#),
            "observations: 12 names, but the [mujoco] model observes 11 values",
        ),
        (
            with(r#", "foot_torque"]"#, "]"),
            "actions: 2 names, but the [mujoco] model has 3 actuators",
        ),
        (
            with("name = \"my-hopper\"", "name = \"my-hopper\"\ndt = 0.01"),
            "dt: 0.01 s, but the [mujoco] model's observations are 0.008 s apart",
        ),
        (
            with(
                "name = \"my-hopper\"",
                "name = \"my-hopper\"\naction_low = [-1.0, -1.0, -2.0]\naction_high = [1.0, 1.0, 1.0]",
            ),
            "action 2 has [-2, 1], but the [mujoco] model's control range is [-1, 1]",
        ),
        (
            with(
                "name = \"my-hopper\"",
                "name = \"my-hopper\"\naction_low = [-1.0, -1.0, -1.0]",
            ),
            "action_low, action_high: give both",
        ),
    ];
    for (header, needle) in cases {
        let message = SystemSpec::read(&hopper_file(dir.path(), &header))
            .unwrap_err()
            .to_string();
        assert!(
            message.contains("my-hopper.toml: ") && message.contains(needle),
            "wanted `{needle}`, got: {message}"
        );
    }
    // Agreeing values are accepted: dt as written in decimal, the model's box.
    let agreeing = with(
        "name = \"my-hopper\"",
        "name = \"my-hopper\"\ndt = 0.008\naction_low = [-1.0, -1.0, -1.0]\naction_high = [1.0, 1.0, 1.0]",
    );
    SystemSpec::read(&hopper_file(dir.path(), &agreeing)).unwrap();

    let file = hopper_file(dir.path(), HOPPER_NAMES);
    std::fs::remove_file(dir.path().join("hopper.xml")).unwrap();
    let message = SystemSpec::read(&file).unwrap_err().to_string();
    assert!(
        message.contains("mujoco.model: cannot read `") && message.contains("hopper.xml"),
        "{message}"
    );
    // Without a table, dt is the file's to give.
    let message = SystemSpec::parse(
        &HOPPER_NAMES.replace(
            "name = \"my-hopper\"",
            "name = \"x\"\naction_low = [-1.0, -1.0, -1.0]\naction_high = [1.0, 1.0, 1.0]",
        ),
        Path::new("x.toml"),
    )
    .unwrap_err()
    .to_string();
    assert!(message.contains("dt: required"), "{message}");
}
