//! Systems described as data (`envs::SystemSpec`) and their CSV logs
//! (`data::read_csv_log`): the issue's example file reads into the split,
//! reward and bounds its names say, in any observation order; reward
//! expressions give a hand computation's values over a batch; a log's rows
//! become the transitions a hand reading gives; every kind of bad file or log
//! is refused naming the key, or the line and the column, and the reason.

use std::path::Path;

use nuno::envs::{EnvError, SystemReward, SystemSpec};

/// The issue's example, with an expression reward.
const CART_POLE: &str = r#"
name = "my-arm"
dt = 0.04
observations = ["x", "theta", "x_dot", "theta_dot"]
actions = ["force"]
action_low = [-3.0]
action_high = [3.0]

[physics]
pairs = [["x", "x_dot"], ["theta", "theta_dot"]]
angles = ["theta"]

[reward]
expression = "1.0 - 0.001 * force^2 - (next_theta - theta)^2 / 4"

[termination]
bounds = { theta = [-0.2, 0.2] }
"#;

fn parse(text: &str) -> Result<SystemSpec, EnvError> {
    SystemSpec::parse(text, Path::new("arm.toml"))
}

/// The message a bad file gets.
fn refused(text: &str) -> String {
    match parse(text) {
        Ok(spec) => panic!("accepted: {spec:?}"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn the_example_reads_into_its_split_reward_and_bounds() {
    let spec = parse(CART_POLE).unwrap();
    assert_eq!((spec.name.as_str(), spec.dt), ("my-arm", 0.04));
    assert_eq!((spec.obs_dim(), spec.act_dim()), (4, 1));
    assert_eq!(spec.split.positions, [0, 1]);
    assert_eq!(spec.split.position_velocity, [2, 3]);
    assert_eq!(spec.split.velocities, [2, 3]);
    assert_eq!(spec.split.angles, [1]);
    let SystemReward::Expression(reward) = &spec.reward else {
        panic!("{:?}", spec.reward)
    };
    // Two transitions, by hand: 1 − 0.001·f² − (θ' − θ)²/4.
    let obs = [0.0, 0.1, 0.0, 0.0, 1.0, -0.1, 2.0, 3.0];
    let next = [0.5, 0.3, 0.0, 0.0, 1.0, -0.1, 2.0, 3.0];
    let actions = [2.0, -3.0];
    let r = reward.rewards((&obs, &actions, &next), (4, 1));
    let by_hand = [1.0 - 0.004 - 0.04 / 4.0, 1.0 - 0.009];
    for (got, want) in r.iter().zip(by_hand) {
        assert!(
            (f64::from(*got) - want).abs() < 1e-6,
            "{r:?} against {by_hand:?}"
        );
    }
    // θ in [−0.2, 0.2] while the episode lasts.
    assert!(!spec.terminated(&[9.0, 0.2, 9.0, 9.0]));
    assert!(spec.terminated(&[0.0, 0.21, 0.0, 0.0]));
    assert!(spec.terminated(&[0.0, -0.3, 0.0, 0.0]));
}

#[test]
fn the_split_follows_the_names_not_the_order() {
    let shuffled = CART_POLE.replace(
        r#"observations = ["x", "theta", "x_dot", "theta_dot"]"#,
        r#"observations = ["theta_dot", "x", "extra", "x_dot", "theta"]"#,
    );
    let spec = parse(&shuffled).unwrap();
    assert_eq!(spec.split.positions, [1, 4]);
    assert_eq!(spec.split.position_velocity, [3, 0]);
    // The unpaired observation is left to the learned drift.
    assert_eq!(spec.split.velocities, [0, 2, 3]);
    assert_eq!(spec.split.angles, [4]);
    // Without [physics], everything is learned.
    let start = CART_POLE.find("[physics]").unwrap();
    let end = CART_POLE.find("[reward]").unwrap();
    let learned_only = format!("{}{}", &CART_POLE[..start], &CART_POLE[end..]);
    let spec = parse(&learned_only).unwrap();
    assert!(spec.split.positions.is_empty());
    assert_eq!(spec.split.velocities, [0, 1, 2, 3]);
    // A learned reward and no termination.
    let learned = learned_only
        .replace(
            r#"expression = "1.0 - 0.001 * force^2 - (next_theta - theta)^2 / 4""#,
            "learned = true",
        )
        .replace("[termination]\nbounds = { theta = [-0.2, 0.2] }", "");
    let spec = parse(&learned).unwrap();
    assert!(matches!(spec.reward, SystemReward::Learned));
    assert!(!spec.terminated(&[1e6, 1e6, 1e6, 1e6]));
}

#[test]
fn bad_files_are_refused_naming_the_key_and_the_reason() {
    let with = |from: &str, to: &str| {
        assert!(CART_POLE.contains(from), "{from}");
        CART_POLE.replace(from, to)
    };
    let cases = [
        (with("dt = 0.04", "dt = 0"), "dt: must be a positive"),
        (with("dt = 0.04", "dt = -1.0"), "dt: must be a positive"),
        (
            with(r#"actions = ["force"]"#, r#"actions = ["x"]"#),
            "actions: `x` is named twice",
        ),
        (
            with(r#"actions = ["force"]"#, r#"actions = ["next_force"]"#),
            "names may not start with next_",
        ),
        (
            with(r#"actions = ["force"]"#, r#"actions = ["2force"]"#),
            "actions: `2force` is not a name",
        ),
        (
            with("action_high = [3.0]", "action_high = [-3.0]"),
            "action 0 has the interval [-3, -3]",
        ),
        (
            with("action_high = [3.0]", "action_high = [3.0, 4.0]"),
            "action_high: 2 values for 1 actions",
        ),
        (
            with(r#"["theta", "theta_dot"]"#, r#"["theta", "omega"]"#),
            "physics.pairs: `omega` is not an observation",
        ),
        (
            with(r#"["theta", "theta_dot"]"#, r#"["theta", "x_dot"]"#),
            "physics.pairs: [`theta`, `x_dot`]: each observation may be in one pair",
        ),
        (
            with(r#"angles = ["theta"]"#, r#"angles = ["phi"]"#),
            "physics.angles: `phi` is not an observation",
        ),
        (
            with(r#"angles = ["theta"]"#, r#"angles = ["x_dot"]"#),
            "physics.angles: `x_dot` is not the position of a pair",
        ),
        (
            with("theta = [-0.2, 0.2]", "phi = [-0.2, 0.2]"),
            "termination.bounds: `phi` is not an observation",
        ),
        (
            with("theta = [-0.2, 0.2]", "theta = [0.2, -0.2]"),
            "termination.bounds: `theta` has [0.2, -0.2]",
        ),
        (
            with("- 0.001 * force^2", "- 0.001 * torque^2"),
            "reward.expression: `torque` is not an observation",
        ),
        (
            with("1.0 - 0.001 * force^2", "1.0 - * force^2"),
            "reward.expression: `1.0 - * force^2",
        ),
        (
            with("[reward]\n", "[reward]\nlearned = true\n"),
            "reward: give learned = true or an expression, not both",
        ),
        (
            with(
                r#"expression = "1.0 - 0.001 * force^2 - (next_theta - theta)^2 / 4""#,
                "learned = false",
            ),
            "reward: give learned = true or an expression",
        ),
        (
            with("dt = 0.04", "dt = 0.04\nframe_skip = 4"),
            "unknown field `frame_skip`",
        ),
        (with("name = \"my-arm\"\n", ""), "missing field `name`"),
    ];
    for (text, needle) in cases {
        let message = refused(&text);
        assert!(
            message.starts_with("arm.toml: ") && message.contains(needle),
            "wanted `{needle}`, got: {message}"
        );
    }
    let missing = SystemSpec::read(Path::new("no/such/system.toml")).unwrap_err();
    assert!(
        missing
            .to_string()
            .contains("no/such/system.toml: cannot read it"),
        "{missing}"
    );
}

/// A CSV log of the example system (its header, then `rows`) in `dir`.
fn csv_log(dir: &Path, header: &str, rows: &[&str]) -> std::path::PathBuf {
    let path = dir.join("log.csv");
    std::fs::write(&path, format!("{header}\n{}\n", rows.join("\n"))).unwrap();
    path
}

const HEADER: &str = "t,episode,theta_dot,x,x_dot,theta,force,reward,terminal,timeout,note";

#[test]
fn a_csv_log_reads_into_the_transitions_its_rows_make() {
    let spec = parse(CART_POLE).unwrap();
    let dir = tempfile::tempdir().unwrap();
    // Two episodes: 3 rows (2 transitions, ended at a time limit), then 2
    // rows (1 transition, terminal); columns in another order than the
    // system's, an extra one ignored, quoted fields read as CSV.
    let rows = [
        "0.00,a,0.1,1.0,0.5,0.01,1.0,0.9,0,0,\"first, row\"",
        "0.04,a,0.2,1.1,0.6,0.02,-1.0,0.8,0,0,",
        "0.08,a,0.3,1.2,0.7,0.03,0.0,0.0,0,1,",
        "0.00,b,0.0,0.0,0.0,0.10,2.0,0.5,0,0,",
        "0.04,b,0.0,0.0,0.0,0.25,0.0,0.0,1,0,",
    ];
    let data = nuno::data::read_csv_log(&csv_log(dir.path(), HEADER, &rows), &spec).unwrap();
    assert_eq!(data.len(), 3);
    // The system's order: x, theta, x_dot, theta_dot.
    assert_eq!(data.observations.row(0).to_vec(), [1.0, 0.01, 0.5, 0.1]);
    assert_eq!(
        data.next_observations.row(1).to_vec(),
        [1.2, 0.03, 0.7, 0.3]
    );
    assert_eq!(data.observations.row(2).to_vec(), [0.0, 0.1, 0.0, 0.0]);
    assert_eq!(data.actions.column(0).to_vec(), [1.0, -1.0, 2.0]);
    assert_eq!(data.rewards.to_vec(), [0.9, 0.8, 0.5]);
    assert_eq!(data.terminals, [false, false, true]);
    assert_eq!(data.timeouts, [false, true, false]);
    assert_eq!(data.trajectories().len(), 2);

    // Without a reward column, the system's expression gives the rewards:
    // 1 − 0.001·f² − (θ' − θ)²/4 by hand.
    let header = "episode,theta_dot,x,x_dot,theta,force";
    let rows = ["a,0.1,1.0,0.5,0.01,1.0", "a,0.2,1.1,0.6,0.03,-1.0"];
    let data = nuno::data::read_csv_log(&csv_log(dir.path(), header, &rows), &spec).unwrap();
    let by_hand = 1.0 - 0.001 - (0.03f64 - 0.01).powi(2) / 4.0;
    assert!(
        (f64::from(data.rewards[0]) - by_hand).abs() < 1e-6,
        "{}",
        data.rewards[0]
    );
    // A learned reward needs the column.
    let learned = CART_POLE.replace(
        r#"expression = "1.0 - 0.001 * force^2 - (next_theta - theta)^2 / 4""#,
        "learned = true",
    );
    let learned = parse(&learned).unwrap();
    let error =
        nuno::data::read_csv_log(&csv_log(dir.path(), header, &rows), &learned).unwrap_err();
    assert!(error.to_string().contains("no `reward` column"), "{error}");
}

#[test]
fn bad_csv_logs_are_refused_naming_the_line_and_the_column() {
    let spec = parse(CART_POLE).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let good = "0.04,a,0.2,1.1,0.6,0.02,-1.0,0.8,0,0,";
    let cases = [
        (
            HEADER.replace(",force", ",torque"),
            vec![good],
            "line 1: no column `force`",
        ),
        (
            HEADER.replace("episode,", "run,"),
            vec![good],
            "no column `episode`",
        ),
        (
            HEADER.into(),
            vec![good, "0.08,a,0.2,1.1,NaN,0.02,-1.0,0.8,0,0,"],
            "line 3, column `x_dot`: NaN is not finite",
        ),
        (
            HEADER.into(),
            vec![good, "0.08,a,0.2,1.1,fast,0.02,-1.0,0.8,0,0,"],
            "line 3, column `x_dot`: `fast` is not a number",
        ),
        (
            HEADER.into(),
            vec![good, "0.08,a,0.2,1.1,0.6,0.02,-1.0,0.8,yes,0,"],
            "line 3, column `terminal`: `yes` is not 0 or 1",
        ),
        (
            HEADER.into(),
            vec![good, "0.04,a,0.2,1.1,0.6,0.02,-1.0,0.8,0,0,"],
            "line 3, column `t`: 0.04 does not increase",
        ),
        (
            HEADER.into(),
            vec![
                good,
                "0.08,a,0.2,1.1,0.6,0.02,-1.0,0.8,0,0,",
                "0.00,b,0.2,1.1,0.6,0.02,-1.0,0.8,0,0,",
                "0.04,a,0.2,1.1,0.6,0.02,-1.0,0.8,0,0,",
            ],
            "line 5: episode `a` continues after another episode",
        ),
        (
            HEADER.into(),
            vec![
                "0.04,a,0.2,1.1,0.6,0.02,-1.0,0.8,1,0,",
                "0.08,a,0.2,1.1,0.6,0.02,-1.0,0.8,0,0,",
            ],
            "line 2: a terminal or timeout flag before the episode's last row",
        ),
        (HEADER.into(), vec![good, "0.08,a,0.2"], "line 3:"),
        (
            format!("{HEADER},x"),
            vec![good],
            "column `x` appears twice",
        ),
    ];
    for (header, rows, needle) in cases {
        let error = nuno::data::read_csv_log(&csv_log(dir.path(), &header, &rows), &spec)
            .expect_err(needle)
            .to_string();
        assert!(
            error.contains("log.csv") && error.contains(needle),
            "wanted `{needle}`, got: {error}"
        );
    }
    // One row per episode makes no transition.
    let error = nuno::data::read_csv_log(&csv_log(dir.path(), HEADER, &[good]), &spec).unwrap_err();
    assert!(error.to_string().contains("no transitions"), "{error}");
    // A missing log is named as missing, by the same reader every command uses.
    let missing = dir.path().join("missing.csv");
    let system = nuno::envs::System::File(std::sync::Arc::new(spec));
    let error = nuno::data::read_system_dataset(&missing, None, &system).unwrap_err();
    assert!(
        matches!(&error, nuno::data::DataError::Io { source, .. }
            if source.kind() == std::io::ErrorKind::NotFound),
        "{error}"
    );
    assert!(error.to_string().contains("missing.csv"), "{error}");
}

#[test]
fn an_npz_with_d4rl_keys_reads_as_d4rl_reads_it() {
    use ndarray::{Array1, Array2};
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("log.npz");
    // Five rows, no `next_observations`: a terminal at row 1, a time limit at
    // row 4. Next states come from the following rows, and each trajectory's
    // last row, whose next state is unknown, is dropped (D4RL's rule).
    let observations = Array2::from_shape_fn((5, 2), |(i, j)| (10 * i + j) as f32);
    let mut npz = ndarray_npy::NpzWriter::new(std::fs::File::create(&path).unwrap());
    npz.add_array("observations", &observations).unwrap();
    npz.add_array("actions", &Array2::from_shape_fn((5, 1), |(i, _)| i as f64))
        .unwrap();
    npz.add_array("rewards", &Array1::from(vec![0.5f32, 1.5, 2.5, 3.5, 4.5]))
        .unwrap();
    npz.add_array(
        "terminals",
        &Array1::from(vec![false, true, false, false, false]),
    )
    .unwrap();
    npz.add_array(
        "timeouts",
        &Array1::from(vec![false, false, false, false, true]),
    )
    .unwrap();
    npz.finish().unwrap();
    let data = nuno::data::read_dataset(&path, None).unwrap();
    // Row 0 → 1 (row 1 ends its trajectory, so row 0 now ends it), rows 2 → 3 → 4.
    assert_eq!(data.len(), 3);
    assert_eq!(data.observations.column(0).to_vec(), [0.0, 20.0, 30.0]);
    assert_eq!(
        data.next_observations.column(1).to_vec(),
        [11.0, 31.0, 41.0]
    );
    assert_eq!(data.actions.column(0).to_vec(), [0.0, 2.0, 3.0]);
    assert_eq!(data.rewards.to_vec(), [0.5, 2.5, 3.5]);
    assert_eq!(data.trajectories().len(), 2);
}

/// A log of x_dot = v and theta_dot = w held constant per episode, with
/// positions advancing by exactly v·dt and w·dt: the declared pairs hold.
fn constant_velocity_log(dir: &Path, dt: f64) -> std::path::PathBuf {
    let mut rows = Vec::new();
    for (e, (v, w)) in [(1.0, -0.5), (-2.0, 0.25)].into_iter().enumerate() {
        for k in 0..20 {
            let t = f64::from(k) * dt;
            rows.push(format!("{e},{},{},{v},{w},0.5", v * t, w * t));
        }
    }
    let rows: Vec<&str> = rows.iter().map(String::as_str).collect();
    csv_log(dir, "episode,x,theta,x_dot,theta_dot,force", &rows)
}

#[test]
fn the_check_finds_a_wrong_dt_and_a_wrong_pair() {
    let dir = tempfile::tempdir().unwrap();
    let spec = parse(CART_POLE).unwrap();
    let log = constant_velocity_log(dir.path(), 0.04);
    let data = nuno::data::read_csv_log(&log, &spec).unwrap();
    let report = nuno::data::check_system(&data, &spec);
    assert!(report.passed(), "{report:?}");
    assert_eq!((report.transitions, report.episodes), (38, 2));
    for pair in &report.pairs {
        assert!(pair.best() < 1e-5, "{pair:?}");
        assert!((pair.fitted_dt - 0.04).abs() < 1e-6, "{pair:?}");
    }
    // The same log declared at half its step: (Δx / 0.02) = 2·v, an error of 1.
    let half = parse(&CART_POLE.replace("dt = 0.04", "dt = 0.02")).unwrap();
    let report = nuno::data::check_system(&data, &half);
    assert!(!report.passed());
    assert!(
        (report.pairs[0].against_velocity - 1.0).abs() < 1e-4,
        "{report:?}"
    );
    assert!((report.pairs[0].fitted_dt - 0.04).abs() < 1e-6);
    // Velocities paired with the wrong positions.
    let swapped = parse(&CART_POLE.replace(
        r#"pairs = [["x", "x_dot"], ["theta", "theta_dot"]]"#,
        r#"pairs = [["x", "theta_dot"], ["theta", "x_dot"]]"#,
    ))
    .unwrap();
    assert!(!nuno::data::check_system(&data, &swapped).passed());
    // An action outside the box is counted.
    let narrow = parse(&CART_POLE.replace("action_high = [3.0]", "action_high = [0.4]")).unwrap();
    let report = nuno::data::check_system(&data, &narrow);
    assert_eq!(report.actions_outside_box, [38]);
    assert!(!report.passed());
}
