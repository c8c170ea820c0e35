//! `nuno-trainer analyze` end to end: the shipped SDE and a small ensemble
//! compared on in- and out-of-distribution data and with the shipped policy;
//! every figure's CSV and SVG written; bad flags named.

mod common;

use std::path::Path;

use common::{fails, generate_hopper, ok, tiny_fit_ensemble};

#[test]
fn analyze_writes_every_figure_for_both_model_kinds() {
    let tmp = tempfile::tempdir().unwrap();
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let (inside, outside, ensemble, out) = (
        tmp.path().join("random.hdf5"),
        tmp.path().join("other.hdf5"),
        tmp.path().join("ensemble"),
        tmp.path().join("analysis"),
    );
    generate_hopper(&s(&inside), 1500, 0);
    // Another random network's data: out of the first one's distribution.
    generate_hopper(&s(&outside), 1500, 7);
    tiny_fit_ensemble(&inside, &ensemble);
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/hopper-random");
    let analyze = |extra: &[&str]| -> Vec<String> {
        let mut args: Vec<String> = [
            "analyze",
            "--model",
            &format!("nuno={}", s(&shipped)),
            "--model",
            &format!("mopo={}", s(&ensemble)),
            "--dataset",
            &s(&inside),
            "--horizon",
            "8",
            "--windows",
            "40",
            "--particles",
            "2",
            "--probe-states",
            "300",
            "--episodes",
            "2",
            "--episode-steps",
            "30",
            "--out",
            &s(&out),
        ]
        .map(String::from)
        .to_vec();
        args.extend(extra.iter().map(|e| e.to_string()));
        args
    };
    let printed = ok(&analyze(&[
        "--ood-dataset",
        &s(&outside),
        "--policy",
        &s(&shipped),
    ]));
    let csv = |name: &str| std::fs::read_to_string(out.join(name)).unwrap();
    // Two models × two datasets × 8 steps.
    let prediction = csv("prediction_error.csv");
    assert_eq!(prediction.lines().count(), 1 + 2 * 2 * 8, "{prediction}");
    // Every window reaches step 1; a step no window reached (the tiny
    // ensemble's hoppers fall) has no error to report.
    for line in prediction.lines().skip(1) {
        let fields: Vec<&str> = line.split(',').collect();
        let (step, rmse, windows): (usize, f64, usize) = (
            fields[2].parse().unwrap(),
            fields[3].parse().unwrap(),
            fields[4].parse().unwrap(),
        );
        if step == 1 {
            assert_eq!(windows, 40, "{line}");
        }
        assert_eq!(windows > 0, rmse.is_finite() && rmse >= 0.0, "{line}");
    }
    // Two models × dataset, random, policy actions.
    let uncertainty = csv("uncertainty.csv");
    assert_eq!(uncertainty.lines().count(), 1 + 2 * 3, "{uncertainty}");
    assert!(uncertainty.contains("mopo,random,") && uncertainty.contains("nuno,policy,"));
    let exploitation = csv("exploitation.csv");
    assert_eq!(exploitation.lines().count(), 1 + 2 * 30);
    // Where each model's states and the real task's leave the data, per step and printed.
    assert!(
        exploitation.starts_with(
            "model,step,real,model,model_penalized,real_outside_data,model_outside_data\n"
        ),
        "{exploitation}"
    );
    for model in ["nuno", "mopo"] {
        let line =
            format!("{model}: states outside the dataset's range after steps 1 / 5 / 20 / 30");
        assert!(printed.contains(&line), "{printed}");
    }
    for figure in [
        "prediction_error.svg",
        "uncertainty.svg",
        "exploitation.svg",
    ] {
        assert!(out.join(figure).is_file(), "{figure}");
    }
    // The least-squares linear model joins Figure 5 only; the shipped SDE,
    // fitted on the same kind of data, predicts a step far better than it.
    ok(&analyze(&["--linear-baseline"]));
    let prediction = csv("prediction_error.csv");
    assert_eq!(prediction.lines().count(), 1 + 3 * 8, "{prediction}");
    let step_one = |model: &str| -> f64 {
        let line = prediction
            .lines()
            .find(|l| l.starts_with(&format!("{model},in-distribution,1,")))
            .unwrap_or_else(|| panic!("no step 1 of {model}: {prediction}"));
        line.split(',').nth(3).unwrap().parse().unwrap()
    };
    let (sde, linear) = (step_one("nuno"), step_one("linear least squares"));
    assert!(sde < linear, "SDE {sde} against linear {linear}");
    // ∂s′/∂a of each model against the simulator's, at dataset, random and
    // saturated actions: the simulator's own is the same whichever model sits
    // beside it, and a linear model's is one matrix wherever it is taken.
    let sensitivity = csv("action_sensitivity.csv");
    assert!(
        sensitivity
            .starts_with("model,actions,model_norm,task_norm,error_norm,median_ratio,states\n"),
        "{sensitivity}"
    );
    assert_eq!(sensitivity.lines().count(), 1 + 3 * 3, "{sensitivity}");
    let norms = |model: &str, column: usize| -> Vec<f64> {
        (sensitivity.lines())
            .filter(|l| l.starts_with(&format!("{model},")))
            .map(|l| l.split(',').nth(column).unwrap().parse().unwrap())
            .collect()
    };
    let (sde_task, linear_task) = (norms("nuno", 3), norms("linear least squares", 3));
    assert_eq!(sde_task, linear_task, "{sensitivity}");
    assert!(sde_task.iter().all(|&n| n > 0.0), "{sensitivity}");
    let linear = norms("linear least squares", 2);
    for n in &linear {
        assert!((n / linear[0] - 1.0).abs() < 1e-2, "{sensitivity}");
    }
    // Bad input, named.
    let error = fails(&analyze(&["--horizon", "0"]));
    assert!(error.contains("--horizon"), "{error}");
    let error = fails(&analyze(&["--action-delta", "0"]));
    assert!(error.contains("--action-delta"), "{error}");
    let error = fails(&[
        "analyze",
        "--model",
        &s(tmp.path()),
        "--dataset",
        &s(&inside),
        "--out",
        &s(&out),
    ]);
    assert!(error.contains("loading the model"), "{error}");
}
