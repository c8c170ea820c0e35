//! Running `nuno-trainer` from the trainer's integration tests.
// Each test crate uses only some of these.
#![allow(dead_code)]

use std::path::Path;
use std::process::{Command, Output};

/// The library's test helpers: the Python peer and the bounded waits.
#[path = "../../../tests/common/mod.rs"]
pub mod peer;
use peer::bounded;

pub fn trainer<S: AsRef<str>>(args: &[S]) -> Output {
    let args: Vec<&str> = args.iter().map(|a| a.as_ref()).collect();
    let mut command = Command::new(env!("CARGO_BIN_EXE_nuno-trainer"));
    command.args(&args);
    bounded::output_within(&mut command, &format!("nuno-trainer {}", args.join(" ")))
}

pub fn ok<S: AsRef<str>>(args: &[S]) -> String {
    let out = trainer(args);
    assert!(
        out.status.success(),
        "nuno-trainer {} failed:\n{}",
        args.iter()
            .map(|a| a.as_ref())
            .collect::<Vec<_>>()
            .join(" "),
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

pub fn fails<S: AsRef<str>>(args: &[S]) -> String {
    let out = trainer(args);
    assert!(
        !out.status.success(),
        "nuno-trainer {} should fail",
        args.iter()
            .map(|a| a.as_ref())
            .collect::<Vec<_>>()
            .join(" ")
    );
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// `nuno-trainer dataset generate`: a small hopper-random dataset at `out`.
pub fn generate_hopper(out: &str, transitions: usize, seed: u64) {
    ok(&[
        "dataset",
        "generate",
        "--task",
        "hopper",
        "--kind",
        "random",
        "--transitions",
        &transitions.to_string(),
        "--seed",
        &seed.to_string(),
        "--out",
        out,
    ]);
}

/// `fit-policy` arguments for a tiny run: `algo` in the model in `model` on
/// `dataset` under the Table 3 row `preset` (none: a system of one's own,
/// h 5, α 1, λ_pen 1), `steps` gradient steps in epochs of 10 (a model
/// rollout of 32 starts each, 16×16 networks, one evaluation episode), into
/// `out`, then `extra`.
pub fn tiny_fit_policy(
    algo: &str,
    model: &Path,
    dataset: &Path,
    preset: Option<&str>,
    steps: usize,
    out: &Path,
    extra: &[&str],
) -> Vec<String> {
    let path = |p: &Path| p.display().to_string();
    let settings = match preset {
        Some(row) => vec!["--preset", row],
        None => vec!["--horizon", "5", "--cvar-alpha", "1", "--penalty", "1"],
    };
    let mut args: Vec<String> = [
        "fit-policy",
        "--algo",
        algo,
        "--model",
        &path(model),
        "--dataset",
        &path(dataset),
    ]
    .iter()
    .chain(&settings)
    .map(|s| s.to_string())
    .collect();
    args.extend(
        [
            "--steps",
            &steps.to_string(),
            "--steps-per-epoch",
            "10",
            "--rollout-freq",
            "10",
            "--rollout-batch",
            "32",
            "--batch-size",
            "32",
            "--hidden",
            "16,16",
            "--eval-episodes",
            "1",
            "--out",
            &path(out),
        ]
        .map(String::from),
    );
    args.extend(extra.iter().map(|e| e.to_string()));
    args
}

/// `fit-ensemble`: a tiny ensemble (3 members, 2 elites, 16×16, 2 epochs) of `dataset` in `out`.
pub fn tiny_fit_ensemble(dataset: &Path, out: &Path) {
    ok(&fit_ensemble_args(dataset, out, &["--max-epochs", "2"]));
}

/// `fit-ensemble`'s arguments for the tiny ensemble above, then `extra`.
pub fn fit_ensemble_args(dataset: &Path, out: &Path, extra: &[&str]) -> Vec<String> {
    let path = |p: &Path| p.display().to_string();
    let mut args: Vec<String> = [
        "fit-ensemble",
        "--dataset",
        &path(dataset),
        "--task",
        "hopper",
        "--out",
        &path(out),
        "--members",
        "3",
        "--elites",
        "2",
        "--hidden",
        "16,16",
        "--weight-decay",
        "2.5e-5,5e-5,1e-4",
    ]
    .map(String::from)
    .to_vec();
    args.extend(extra.iter().map(|e| e.to_string()));
    args
}

/// Copies a folder and everything under it.
pub fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let path = entry.unwrap().path();
        let target = to.join(path.file_name().unwrap());
        if path.is_dir() {
            copy_dir(&path, &target);
        } else {
            std::fs::copy(&path, &target).unwrap();
        }
    }
}
