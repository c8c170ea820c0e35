//! `nuno-trainer evaluate --planner`: model-predictive control in the real
//! task on a tiny budget, for shape and determinism (never for a score), beside
//! the model's own policy; its bad flags are named.

mod common;

use std::path::Path;

use common::{fails, ok};

const TINY: [&str; 8] = [
    "--horizon",
    "3",
    "--population",
    "8",
    "--iterations",
    "2",
    "--episodes",
    "2",
];

fn shipped() -> String {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/hopper-random");
    dir.to_str().unwrap().to_owned()
}

fn mpc(planner: &str, extra: &[&str]) -> serde_json::Value {
    let model = shipped();
    let mut args = vec![
        "evaluate",
        "--planner",
        planner,
        "--model",
        &model,
        "--json",
    ];
    args.extend(TINY);
    args.extend(extra);
    serde_json::from_str(&ok(&args)).unwrap()
}

#[test]
fn mpc_reports_every_planner_beside_the_policy_and_repeats_itself() {
    for planner in ["mppi", "cem", "icem"] {
        let report = mpc(planner, &[]);
        let episodes = report["planner"]["lengths"].as_array().unwrap();
        assert_eq!(episodes.len(), 2, "{report}");
        assert!(episodes.iter().all(|l| l.as_u64().unwrap() >= 1));
        assert!(
            report["planner"]["mean_return"]
                .as_f64()
                .unwrap()
                .is_finite()
        );
        // The shipped folder holds a policy: it is evaluated on the same resets.
        assert_eq!(report["policy"]["returns"].as_array().unwrap().len(), 2);
        assert_eq!(report, mpc(planner, &[]), "{planner} is not repeatable");
    }
    // A different seed resets differently, so the planner's episodes differ.
    assert_ne!(
        mpc("cem", &[])["planner"],
        mpc("cem", &["--seed", "9"])["planner"]
    );
}

#[test]
fn the_planners_bad_flags_are_named() {
    let model = shipped();
    let base = |extra: &[&str]| {
        let mut args = vec!["evaluate", "--model", &model];
        args.extend(TINY);
        args.extend(extra.iter().copied());
        args.into_iter().map(str::to_owned).collect::<Vec<_>>()
    };
    let err = fails(&base(&["--planner", "ilqr"]));
    assert!(err.contains("unknown planner \"ilqr\""), "{err}");
    let err = fails(&base(&["--planner", "mppi", "--elites", "2"]));
    assert!(
        err.contains("`elites` and `momentum` are settings of cem"),
        "{err}"
    );
    let err = fails(&base(&["--planner", "cem", "--temperature", "2"]));
    assert!(err.contains("settings of mppi"), "{err}");
    let err = fails(&base(&["--planner", "cem", "--keep-elites", "0.5"]));
    assert!(
        err.contains("`decay`, `colored_noise` and `keep_elites` are settings of icem"),
        "{err}"
    );
    let err = fails(&base(&["--planner", "icem", "--decay", "0.5"]));
    assert!(err.contains("decay 0.5 is not a number ≥ 1"), "{err}");
    let err = fails(&base(&["--planner", "mppi", "--temperature=-1"]));
    assert!(err.contains("temperature -1 is not a number > 0"), "{err}");
    let err = fails(&base(&["--planner", "mppi", "--alpha", "0.42"]));
    assert!(err.contains("no ε(h = 3, α = 0.42)"), "{err}");
    // The planner's flags without a planner, and a folder without a model.
    let err = fails(&["evaluate", "--policy", &model, "--horizon", "3"]);
    assert!(err.contains("--planner"), "{err}");
    let empty = tempfile::tempdir().unwrap();
    let dir = empty.path().to_str().unwrap();
    let err = fails(&["evaluate", "--planner", "cem", "--model", dir]);
    assert!(err.contains("loading the model in"), "{err}");
}
