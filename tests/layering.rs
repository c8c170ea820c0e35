//! The library's folders depend on each other in one direction only: every
//! `crate::<folder>` a source file names must be a folder below its own
//! (docs/architecture.md). An arrow that runs back up fails here, naming the
//! file and the line.

use std::path::{Path, PathBuf};

/// Each folder (or top-level module) and what it may import, bottom first.
const LAYERS: &[(&str, &[&str])] = &[
    ("shared", &[]),
    ("nn", &["shared"]),
    ("envs", &["shared"]),
    ("data", &["shared", "envs"]),
    ("infer", &["shared", "nn"]),
    ("sde", &["shared", "nn", "infer", "envs", "data"]),
    ("ensemble", &["shared", "nn", "infer", "envs", "data"]),
    (
        "agent",
        &["shared", "nn", "infer", "envs", "data", "sde", "ensemble"],
    ),
    (
        "planning",
        &[
            "shared", "nn", "infer", "envs", "data", "sde", "ensemble", "agent",
        ],
    ),
    (
        "artifact",
        &[
            "shared", "nn", "infer", "envs", "data", "sde", "ensemble", "agent", "planning",
        ],
    ),
    (
        "export",
        &[
            "shared", "nn", "infer", "envs", "data", "sde", "ensemble", "agent", "planning",
            "artifact",
        ],
    ),
    (
        "experiment",
        &[
            "shared", "nn", "infer", "envs", "data", "sde", "ensemble", "agent", "planning",
            "artifact",
        ],
    ),
    (
        "server",
        &[
            "shared", "nn", "infer", "envs", "data", "sde", "ensemble", "agent", "planning",
            "artifact",
        ],
    ),
];

fn rust_files(dir: &Path, found: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            rust_files(&path, found);
        } else if path.extension().is_some_and(|e| e == "rs") {
            found.push(path);
        }
    }
}

/// The `crate::<name>` paths on a line of code (comments skipped).
fn crate_paths(line: &str) -> Vec<&str> {
    let code = line.split("//").next().unwrap_or("");
    code.match_indices("crate::")
        .map(|(at, _)| {
            let rest = &code[at + "crate::".len()..];
            let end = rest
                .find(|c: char| !(c.is_alphanumeric() || c == '_'))
                .unwrap_or(rest.len());
            &rest[..end]
        })
        .collect()
}

#[test]
fn every_folder_imports_only_the_ones_below_it() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let mut violations = Vec::new();
    let mut checked = 0;
    for file in &files {
        let relative = file.strip_prefix(&src).unwrap();
        let top = relative
            .components()
            .next()
            .unwrap()
            .as_os_str()
            .to_string_lossy();
        let folder = top.trim_end_matches(".rs");
        // lib.rs declares and re-exports; the binaries sit on top of everything.
        let Some((_, allowed)) = LAYERS.iter().find(|(name, _)| *name == folder) else {
            assert!(
                ["lib", "bin"].contains(&folder),
                "{} is in no layer: add its folder to LAYERS and docs/architecture.md",
                relative.display()
            );
            continue;
        };
        let text = std::fs::read_to_string(file).unwrap();
        for (number, line) in text.lines().enumerate() {
            for name in crate_paths(line) {
                checked += 1;
                if name != folder && !allowed.contains(&name) {
                    violations.push(format!(
                        "{}:{}: {folder} imports crate::{name}",
                        relative.display(),
                        number + 1
                    ));
                }
            }
        }
    }
    assert!(
        checked > 100,
        "only {checked} crate paths found: is src/ laid out as expected?"
    );
    assert!(
        violations.is_empty(),
        "arrows that run up:\n{}",
        violations.join("\n")
    );
}

#[test]
fn the_path_scanner_reads_paths_and_skips_comments() {
    assert_eq!(
        crate_paths("use crate::sde::{BatchDynamics, crate::x}; // crate::agent"),
        ["sde", "x"]
    );
    assert!(crate_paths("/// see [`crate::agent::Sac`]").is_empty());
}
