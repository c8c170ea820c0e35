//! Systems described as data (`envs::SystemSpec`): the issue's example file
//! reads into the split, reward and bounds its names say, in any observation
//! order; reward expressions give a hand computation's values over a batch;
//! every kind of bad file is refused naming the key and the reason.

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
