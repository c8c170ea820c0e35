//! `nuno-trainer fit-model`'s η loss, h(η) and threshold flags: bad values are named before any
//! work starts, and nothing is written.

mod common;

use common::fails;

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
