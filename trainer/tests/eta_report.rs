//! `nuno-trainer eta-report` on the shipped model: a table, the same report as
//! JSON, and bad flags or paths named.

mod common;

use std::path::Path;

use common::{fails, generate_hopper, ok};

#[test]
fn eta_report_prints_a_table_and_json_and_names_bad_input() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tmp.path().join("hopper.hdf5");
    let data_arg = data.to_str().unwrap();
    generate_hopper(data_arg, 2000, 3);
    let model = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/hopper-random");
    let model_arg = model.to_str().unwrap();
    let report = ["eta-report", "--model", model_arg, "--dataset", data_arg];

    let fast = ["--rows", "300", "--windows", "32"];
    let table = ok(&[&report[..], &fast].concat());
    assert!(table.contains("η on 300 dataset transitions"), "{table}");
    for row in [
        "random actions",
        "(1·r)²",
        "(3·r)²",
        "Calibration on 300 held-out transitions",
        "| 10 | 0.95 |",
    ] {
        assert!(table.contains(row), "{row} missing:\n{table}");
    }

    let json = ok(&[&report[..], &fast, &["--radii", "2", "--json"]].concat());
    let parsed: serde_json::Value = serde_json::from_str(&json).unwrap();
    let separation = &parsed["separation"];
    assert_eq!(separation["rows"], 300);
    assert_eq!(separation["perturbed"].as_array().unwrap().len(), 1);
    let auroc = separation["perturbed"][0][1]["auroc_vs_data"]
        .as_f64()
        .unwrap();
    assert!((0.0..=1.0).contains(&auroc) && auroc > 0.9, "{json}");
    let calibration = &parsed["calibration"];
    assert_eq!(calibration["dimensions"].as_array().unwrap().len(), 11);
    // The data, k = 2 and the far points.
    assert_eq!(calibration["diffusion"].as_array().unwrap().len(), 3);
    assert_eq!(calibration["horizons"][0]["windows"], 32);

    let stderr = fails(&[&report[..], &["--windows", "0"]].concat());
    assert!(stderr.contains("windows = 0"), "{stderr}");

    let stderr = fails(&[&report[..], &["--radii", "1,-2"]].concat());
    assert!(stderr.contains("perturbation scale -2"), "{stderr}");
    let stderr = fails(&[&report[..], &["--rows", "0"]].concat());
    assert!(stderr.contains("rows = 0"), "{stderr}");
    let missing = tmp.path().join("no-model");
    let stderr = fails(&[
        "eta-report",
        "--model",
        missing.to_str().unwrap(),
        "--dataset",
        data_arg,
    ]);
    assert!(stderr.contains("no-model"), "{stderr}");
}
