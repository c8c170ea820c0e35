//! `nuno-trainer fit-ensemble` end to end: a checkpoint after every epoch,
//! `--resume` continuing to a higher epoch cap, a second fit into the same
//! folder refused, and flags that do not fit the checkpoint or are unknown
//! named.

mod common;

use common::{fails, fit_ensemble_args, generate_hopper, ok};

fn epochs_in(metrics: &std::path::Path) -> usize {
    std::fs::read_to_string(metrics).unwrap().lines().count() - 1
}

#[test]
fn fit_ensemble_checkpoints_and_resumes() {
    let tmp = tempfile::tempdir().unwrap();
    let dataset = tmp.path().join("hopper.hdf5");
    generate_hopper(dataset.to_str().unwrap(), 1500, 0);
    let out = tmp.path().join("ensemble");
    let run = |extra: &[&str]| fit_ensemble_args(&dataset, &out, extra);

    ok(&run(&["--max-epochs", "2"]));
    let checkpoints = out.join("ensemble-checkpoints");
    let latest = std::fs::read_to_string(checkpoints.join("LATEST")).unwrap();
    assert_eq!(latest.trim(), "epoch-000002");
    assert_eq!(epochs_in(&out.join("ensemble_metrics.csv")), 2);

    let again = fails(&run(&["--max-epochs", "3"]));
    assert!(again.contains("--resume"), "{again}");

    let resumed = ok(&run(&["--max-epochs", "3", "--resume", "--kernel", "burn"]));
    assert!(resumed.contains("(epoch 2)"), "{resumed}");
    assert!(resumed.contains("epoch    3:"), "{resumed}");
    assert!(!resumed.contains("epoch    1:"), "{resumed}");
    assert_eq!(epochs_in(&out.join("ensemble_metrics.csv")), 3);
    let metadata: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("ensemble.json")).unwrap()).unwrap();
    assert_eq!(metadata["epochs"], 3);

    // The checkpoint is of 16×16 members; another width cannot continue it.
    let mut wider = run(&["--max-epochs", "4", "--resume"]);
    let hidden = wider.iter().position(|a| a == "16,16").unwrap();
    wider[hidden] = "32,32".into();
    let refused = fails(&wider);
    assert!(refused.contains("other settings or data"), "{refused}");

    let bad = fails(&run(&["--kernel", "cuda"]));
    assert!(bad.contains("unknown kernel `cuda`"), "{bad}");
}
