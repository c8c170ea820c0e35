//! `nuno-trainer fit-model`'s η loss, h(η) and threshold flags: bad values are named before any
//! work starts, and nothing is written; a fit records its resolved settings in run.json,
//! checkpoints at every validation, and `--resume` continues it.

mod common;

use common::{fails, generate_hopper, ok};

#[test]
fn fit_model_names_unusable_loss_flags_before_reading_anything() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("model");
    let out_arg = out.to_str().unwrap();
    for (flag, value, named) in [
        ("--radius", "0", "radius = 0"),
        ("--lambda-grad", "-1", "lambda_grad = -1"),
        ("--lambda-far", "NaN", "lambda_far = NaN"),
        ("--w-max", "1,2", "w_max has 2 values"),
        ("--w-max", "0", "w_max value 0"),
        ("--threshold-windows", "0", "max_windows = 0"),
        ("--threshold-max-margin", "0.5", "max_margin = 0.5"),
        ("--step-discount", "0", "step_discount = 0"),
        ("--step-discount", "1.5", "step_discount = 1.5"),
        ("--recipe", "codes", "unknown recipe \"codes\""),
        ("--sample-noise", "full", "unknown sample noise \"full\""),
        ("--eta-losses", "codes", "unknown eta loss form \"codes\""),
        (
            "--drift-inputs",
            "angles",
            "unknown drift inputs \"angles\"",
        ),
        (
            "--likelihood",
            "teacher",
            "unknown likelihood path \"teacher\"",
        ),
    ] {
        let flag_value = format!("{flag}={value}");
        let stderr = fails(&[
            "fit-model",
            "--dataset",
            "no-such-dataset.hdf5",
            "--task",
            "hopper",
            "--out",
            out_arg,
            flag_value.as_str(),
        ]);
        assert!(
            stderr.contains(named) && stderr.contains(flag),
            "{flag} {value}: {stderr}"
        );
        assert!(!out.exists(), "{flag} {value} left {}", out.display());
    }
}

#[test]
fn fit_model_checkpoints_and_resumes() {
    let tmp = tempfile::tempdir().unwrap();
    let dataset = tmp.path().join("hopper.hdf5");
    generate_hopper(dataset.to_str().unwrap(), 1500, 0);
    let out = tmp.path().join("model");
    let args = |steps: &str, extra: &[&str]| -> Vec<String> {
        let mut a: Vec<String> = [
            "fit-model",
            "--dataset",
            dataset.to_str().unwrap(),
            "--task",
            "hopper",
            "--out",
            out.to_str().unwrap(),
            "--max-steps",
            steps,
            "--eval-every",
            "10",
            "--drift-hidden",
            "16,16",
            "--threshold-windows",
            "32",
        ]
        .map(String::from)
        .to_vec();
        a.extend(extra.iter().map(|e| e.to_string()));
        a
    };
    let valid_steps = |csv: &str| -> Vec<usize> {
        csv.lines()
            .skip(1)
            .filter(|l| !l.ends_with(','))
            .map(|l| l.split(',').next().unwrap().parse().unwrap())
            .collect()
    };
    let first = ok(&args("20", &[]));
    let latest = std::fs::read_to_string(out.join("fit-checkpoints/LATEST")).unwrap();
    assert_eq!(latest.trim(), "step-0000020");
    // run.json: the resolved plan (the flags and the defaults they left), the
    // dataset by coreutils' sha256sum, printed as well.
    let record = || -> serde_json::Value {
        serde_json::from_slice(&std::fs::read(out.join("run.json")).unwrap()).unwrap()
    };
    let run = record();
    assert!(first.contains("the run's settings"), "{first}");
    assert_eq!(run["command"], "fit-model");
    assert_eq!(run["plan"]["fit"]["max_steps"], 20, "{run}");
    assert_eq!(
        run["plan"]["fit"]["model"]["drift_hidden"],
        serde_json::json!([16, 16])
    );
    assert_eq!(
        run["plan"]["fit"]["patience"], 8,
        "the paper recipe's: {run}"
    );
    assert_eq!(run["plan"]["report"]["thresholds"]["max_windows"], 32);
    let sha256sum = common::peer::bounded::output_within(
        std::process::Command::new("sha256sum").arg(&dataset),
        "sha256sum",
    );
    let digest = String::from_utf8_lossy(&sha256sum.stdout);
    assert_eq!(
        run["datasets"][0]["sha256"].as_str(),
        digest.split_whitespace().next()
    );

    let again = fails(&args("30", &[]));
    assert!(again.contains("--resume"), "{again}");
    assert_eq!(
        record()["plan"]["fit"]["max_steps"],
        20,
        "a refused run kept the record"
    );
    let resumed = ok(&args("30", &["--resume"]));
    assert!(resumed.contains("(step 20)"), "{resumed}");
    assert_eq!(record()["plan"]["fit"]["max_steps"], 30);
    let metrics = std::fs::read_to_string(out.join("metrics.csv")).unwrap();
    assert_eq!(valid_steps(&metrics), [10, 20, 30], "{metrics}");
    let model: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("model.json")).unwrap()).unwrap();
    assert_eq!(model["training"]["steps"], 30);

    // While another process writes the folder (its claim held here), a second fit into it
    // is refused before it writes anything; once released, the folder is free again.
    let held = std::fs::File::open(out.join(".writing")).unwrap();
    held.lock().unwrap();
    let busy = fails(&args("40", &["--resume"]));
    assert!(busy.contains("being written by another process"), "{busy}");
    assert_eq!(
        record()["plan"]["fit"]["max_steps"],
        30,
        "the refused fit wrote"
    );
    drop(held);
    let other = fails(&args("40", &["--resume", "--lambda-grad", "0.5"]));
    assert!(other.contains("other settings"), "{other}");
}
