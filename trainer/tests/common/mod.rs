//! Running `nuno-trainer` from the trainer's integration tests.
// Each test crate uses only some of these.
#![allow(dead_code)]

use std::process::{Command, Output};

pub fn trainer<S: AsRef<str>>(args: &[S]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_nuno-trainer"))
        .args(args.iter().map(|a| a.as_ref()))
        .output()
        .expect("could not run nuno-trainer")
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
