//! Behaviour datasets end to end on tiny budgets: `collect online-sac`
//! records D4RL's columns and resumes bit for bit; `collect select` ships the
//! levels; `dataset generate` makes medium, expert, medium-expert,
//! medium-replay and NeoRL's levels with the right sizes, boundaries and
//! metadata, the same bytes for the same seed, read back by nuno, h5py and
//! numpy; bad requests are refused by name before any work.

mod common;

use std::path::{Path, PathBuf};

use common::{copy_dir, fails, ok};
use nuno::artifact::{parse_safetensors, read_run_transitions};
use nuno::data::{Dataset, DatasetFormat, read_dataset};

/// `collect online-sac` on hopper with tiny networks: checkpoints every 300
/// steps, the first 300 uniformly random.
fn online<S: AsRef<str>>(out: &Path, steps: usize, seed: u64, extra: &[S]) -> Vec<String> {
    let mut args: Vec<String> = [
        "collect",
        "online-sac",
        "--task",
        "hopper",
        "--steps",
        &steps.to_string(),
        "--seed",
        &seed.to_string(),
        "--start-steps",
        "300",
        "--checkpoint-every",
        "300",
        "--eval-episodes",
        "2",
        "--hidden",
        "16,16",
        "--batch-size",
        "32",
        "--out",
        out.to_str().unwrap(),
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    args.extend(extra.iter().map(|s| s.as_ref().to_string()));
    args
}

/// What h5py (`inspect-d4rl`) or numpy (`inspect-neorl`) sees in `file`.
fn inspect(command: &str, file: &Path, workdir: &Path) -> serde_json::Value {
    let report = workdir.join(format!("{command}.json"));
    common::peer::run_python(
        "datasets.py",
        &[command.as_ref(), file.as_os_str(), report.as_os_str()],
        workdir,
    );
    serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap()
}

fn read(path: &Path) -> Dataset {
    read_dataset(path, None).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// One recorded interval's named columns, read straight from its safetensors file.
fn interval(path: &Path) -> nuno::artifact::NamedTensors {
    parse_safetensors(&std::fs::read(path).unwrap(), path).unwrap()
}

fn intervals(run: &Path) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(run.join("transitions"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    files
}

#[test]
fn online_sac_records_d4rl_columns_and_resumes_bit_for_bit() {
    let tmp = tempfile::tempdir().unwrap();
    let (straight, resumed) = (tmp.path().join("straight"), tmp.path().join("resumed"));
    ok(&online::<&str>(&straight, 900, 3, &[]));
    ok(&online::<&str>(&resumed, 600, 3, &[]));
    // A second start in the same directory must be asked for.
    let error = fails(&online::<&str>(&resumed, 900, 3, &[]));
    assert!(error.contains("--resume"), "{error}");
    let error = fails(&online(&resumed, 900, 4, &["--resume"]));
    assert!(error.contains("other settings"), "{error}");
    let out = ok(&online(&resumed, 900, 3, &["--resume"]));
    assert!(out.contains("resumed at step 600"), "{out}");

    for file in [
        "transitions/steps-00000600-00000900.safetensors",
        "policies/step-00000900.safetensors",
        "checkpoints/step-00000900/networks.safetensors",
        "checkpoints/step-00000900/adam.safetensors",
    ] {
        assert_eq!(
            std::fs::read(straight.join(file)).unwrap(),
            std::fs::read(resumed.join(file)).unwrap(),
            "{file} differs between the straight and the resumed run"
        );
    }
    let metrics = std::fs::read_to_string(straight.join("metrics.csv")).unwrap();
    assert_eq!(metrics.lines().count(), 4, "{metrics}");
    assert!(straight.join("returns.svg").is_file());

    let files = intervals(&straight);
    assert_eq!(files.len(), 3);
    let first = interval(&files[0]);
    // The warm-up acts uniformly on hopper's box [-1, 1]³: density 2⁻³.
    let uniform = -3.0 * std::f32::consts::LN_2;
    assert!(first["action_log_probs"].1.iter().all(|&l| l == uniform));
    let later = interval(&files[1]);
    assert!(
        later["action_log_probs"]
            .1
            .iter()
            .all(|&l| l != uniform && l.is_finite())
    );
    assert_eq!(first["qpos"].0, vec![300, 6]);
    assert_eq!(first["qvel"].0, vec![300, 6]);
    // Each interval ends its last trajectory: a terminal or a timeout.
    for file in &files {
        let t = interval(file);
        let last = t["rewards"].0[0] - 1;
        assert!(
            t["terminals"].1[last] + t["timeouts"].1[last] == 1.0,
            "{}",
            file.display()
        );
    }
}

/// The metrics.csv column `name`, one value per checkpoint.
fn metric(run: &Path, name: &str) -> Vec<f64> {
    let csv = std::fs::read_to_string(run.join("metrics.csv")).unwrap();
    let mut lines = csv.lines();
    let column = lines
        .next()
        .unwrap()
        .split(',')
        .position(|c| c == name)
        .unwrap_or_else(|| panic!("no column {name}"));
    lines
        .map(|l| l.split(',').nth(column).unwrap().parse().unwrap())
        .collect()
}

#[test]
fn a_snapshot_carries_a_run_to_another_machine() {
    let tmp = tempfile::tempdir().unwrap();
    let p = |name: &str| tmp.path().join(name);
    let s = |path: &Path| path.to_str().unwrap().to_string();
    let (run, snapshot, moved) = (p("run"), p("snapshot"), p("moved"));
    ok(&online::<&str>(&run, 1200, 5, &[]));
    let error = fails(&[
        "collect",
        "snapshot",
        "--run",
        &s(&run),
        "--out",
        &s(&snapshot),
        "--band",
        "0",
    ]);
    assert!(error.contains("band"), "{error}");
    // One band holds every score: the first policy, the best and the latest.
    ok(&[
        "collect",
        "snapshot",
        "--run",
        &s(&run),
        "--out",
        &s(&snapshot),
        "--band",
        "1e6",
    ]);
    let scores = metric(&run, "eval/normalized_score");
    let best = 300
        * (1 + (0..scores.len())
            .max_by(|&a, &b| scores[a].total_cmp(&scores[b]))
            .unwrap());
    let mut expected = vec![300, best, 1200];
    expected.sort();
    expected.dedup();
    let mut kept: Vec<usize> = std::fs::read_dir(snapshot.join("policies"))
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .filter_map(|n| {
            n.strip_suffix(".json")
                .map(|stem| stem["step-".len()..].parse().unwrap())
        })
        .collect();
    kept.sort();
    assert_eq!(kept, expected);
    assert!(!snapshot.join("transitions").exists());
    for file in ["networks.safetensors", "adam.safetensors"] {
        let name = format!("checkpoints/step-00001200/{file}");
        assert_eq!(
            std::fs::read(run.join(&name)).unwrap(),
            std::fs::read(snapshot.join(&name)).unwrap()
        );
    }

    // The replay up to a checkpoint travels with the snapshot: the same files,
    // read back as the same transitions as the run's own.
    let with_replay = p("with-replay");
    let snapshot_with = |step: &str| -> Vec<String> {
        let args = [
            "collect",
            "snapshot",
            "--run",
            &s(&run),
            "--out",
            &s(&with_replay),
        ];
        (args.iter().map(|a| a.to_string()))
            .chain(["--replay-until".to_string(), step.to_string()])
            .collect()
    };
    let error = fails(&snapshot_with("500"));
    assert!(
        error.contains("500") && error.contains("not a checkpoint"),
        "{error}"
    );
    ok(&snapshot_with("600"));
    let mut files: Vec<String> = std::fs::read_dir(with_replay.join("transitions"))
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    files.sort();
    assert_eq!(
        files,
        [
            "steps-00000000-00000300.safetensors.zst",
            "steps-00000300-00000600.safetensors.zst"
        ]
    );
    let first = "transitions/steps-00000000-00000300.safetensors";
    let plain = std::fs::read(run.join(first)).unwrap();
    let kept = std::fs::read(with_replay.join(format!("{first}.zst"))).unwrap();
    assert!(
        kept.len() < plain.len() / 2,
        "{} of {}",
        kept.len(),
        plain.len()
    );
    let (ours, theirs) = (
        read_run_transitions(&with_replay, 600).unwrap(),
        read_run_transitions(&run, 600).unwrap(),
    );
    assert_eq!(ours.len(), 600);
    assert_eq!(ours.observations, theirs.observations);
    assert_eq!(ours.actions, theirs.actions);
    assert_eq!(ours.rewards, theirs.rewards);
    assert_eq!(ours.terminals, theirs.terminals);
    assert_eq!(ours.timeouts, theirs.timeouts);
    let error = read_run_transitions(&with_replay, 900)
        .unwrap_err()
        .to_string();
    assert!(error.contains("not there"), "{error}");
    // A damaged compressed interval is refused by name, never read as data.
    let damaged = p("damaged");
    copy_dir(&with_replay, &damaged);
    let second = damaged.join("transitions/steps-00000300-00000600.safetensors.zst");
    let mut bytes = std::fs::read(&second).unwrap();
    bytes.truncate(bytes.len() / 2);
    std::fs::write(&second, bytes).unwrap();
    let error = read_run_transitions(&damaged, 600).unwrap_err().to_string();
    assert!(
        error.contains("steps-00000300-00000600.safetensors.zst"),
        "{error}"
    );

    // On another machine: the transitions are missing, and continuing must say how.
    copy_dir(&snapshot, &moved);
    let error = fails(&online(&moved, 1500, 5, &["--resume"]));
    assert!(error.contains("--refill"), "{error}");
    let out = ok(&online(&moved, 1800, 5, &["--resume", "--refill", "400"]));
    assert!(
        out.contains("resumed at step 1200 (updates from step 1600)"),
        "{out}"
    );
    // Updates ran after step 300 (one per step) and, continued, after step 1600.
    let updates = metric(&moved, "updates");
    assert_eq!(updates[3], 900.0);
    assert_eq!(updates[5], 900.0 + 200.0);
    let refill = interval(&moved.join("transitions/steps-00001200-00001500.safetensors"));
    let uniform = -3.0 * std::f32::consts::LN_2;
    assert!(
        refill["action_log_probs"]
            .1
            .iter()
            .all(|&l| l != uniform && l.is_finite())
    );
    // The continued run's levels are picked from the policies it holds.
    ok(&[
        "collect",
        "select",
        "--run",
        &s(&moved),
        "--out",
        &s(&p("behaviour")),
        "--levels",
        "expert",
        "--tolerance",
        "1",
    ]);
}

/// `select --episodes` picks on fresh evaluations from the run's start
/// states: its expert is the policy `evaluate` rates best over as many
/// episodes from the same seed, with that return.
#[test]
fn select_can_pick_on_longer_evaluations() {
    let tmp = tempfile::tempdir().unwrap();
    let p = |name: &str| tmp.path().join(name);
    let s = |path: &Path| path.to_str().unwrap().to_string();
    let (run, behaviour) = (p("run"), p("behaviour"));
    ok(&online::<&str>(&run, 1200, 5, &[]));
    let select = |episodes: &str| {
        let args = [
            "collect",
            "select",
            "--run",
            &s(&run),
            "--out",
            &s(&behaviour),
        ];
        (args.iter().map(|a| a.to_string()))
            .chain(
                [
                    "--levels",
                    "expert",
                    "--tolerance",
                    "1",
                    "--episodes",
                    episodes,
                ]
                .map(String::from),
            )
            .collect::<Vec<_>>()
    };
    let error = fails(&select("0"));
    assert!(error.contains("--episodes"), "{error}");
    ok(&select("3"));

    let evaluated: Vec<(u64, f64)> = (1..=4)
        .map(|i| {
            let step = 300 * i;
            let out = ok(&[
                "evaluate",
                "--policy",
                &s(&run.join("policies")),
                "--policy-name",
                &format!("step-{step:08}"),
                "--task",
                "hopper",
                "--episodes",
                "3",
                "--seed",
                "5",
                "--json",
            ]);
            let report: serde_json::Value = serde_json::from_str(&out).unwrap();
            (step, report["mean_return"].as_f64().unwrap())
        })
        .collect();
    let best = evaluated
        .iter()
        .fold(evaluated[0], |b, &e| if e.1 > b.1 { e } else { b });
    let levels: serde_json::Value =
        serde_json::from_slice(&std::fs::read(behaviour.join("hopper/levels.json")).unwrap())
            .unwrap();
    let pick = &levels["levels"]["expert"]["pick"];
    assert_eq!(pick["step"].as_u64(), Some(best.0), "{evaluated:?}");
    assert_eq!(pick["mean_return"].as_f64(), Some(best.1));
    assert_eq!(pick["evaluation_episodes"].as_u64(), Some(3));
}

#[test]
#[cfg_attr(
    not(feature = "external-tests"),
    ignore = "needs the Python venv (`make venv`); `make test` runs it"
)]
fn behaviour_recipes_make_d4rl_and_neorl_datasets() {
    let tmp = tempfile::tempdir().unwrap();
    let p = |name: &str| tmp.path().join(name);
    let s = |path: &Path| path.to_str().unwrap().to_string();
    let (run, behaviour) = (p("run"), p("behaviour"));
    ok(&online::<&str>(&run, 1200, 0, &[]));
    let error = fails(&[
        "collect",
        "select",
        "--run",
        &s(&run),
        "--out",
        &s(&behaviour),
        "--tolerance",
        "0",
    ]);
    assert!(error.contains("--tolerance"), "{error}");
    ok(&[
        "collect",
        "select",
        "--run",
        &s(&run),
        "--out",
        &s(&behaviour),
        "--tolerance",
        "1",
    ]);
    let levels: serde_json::Value =
        serde_json::from_slice(&std::fs::read(behaviour.join("hopper/levels.json")).unwrap())
            .unwrap();
    let step = |level: &str| levels["levels"][level]["pick"]["step"].as_u64().unwrap() as usize;
    let returns: Vec<f64> = std::fs::read_to_string(run.join("metrics.csv"))
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(4).unwrap().parse().unwrap())
        .collect();
    let best = returns.iter().copied().fold(f64::MIN, f64::max);
    assert_eq!(
        step("expert"),
        300 * (1 + returns.iter().position(|&r| r == best).unwrap())
    );

    let generate = |kind: &str, out: &Path, extra: &[&str]| {
        let mut args = vec![
            "dataset".to_string(),
            "generate".into(),
            "--task".into(),
            "hopper".into(),
            "--kind".into(),
            kind.into(),
            "--behaviour".into(),
            s(&behaviour),
            "--out".into(),
            s(out),
        ];
        args.extend(extra.iter().map(|e| e.to_string()));
        args
    };
    let small = ["--transitions", "1500"];
    ok(&generate("medium", &p("medium.hdf5"), &small));
    ok(&generate("expert", &p("expert.hdf5"), &small));
    ok(&generate("medium-expert", &p("medium-expert.hdf5"), &small));
    ok(&generate("medium", &p("medium-again.hdf5"), &small));
    ok(&generate(
        "medium",
        &p("medium-seed-1.hdf5"),
        &["--transitions", "1500", "--seed", "1"],
    ));

    let (medium, expert) = (read(&p("medium.hdf5")), read(&p("expert.hdf5")));
    for (name, d, level) in [("medium", &medium, "medium"), ("expert", &expert, "expert")] {
        assert_eq!(d.len(), 1500, "{name}");
        let last = d.len() - 1;
        assert!(
            d.terminals[last] || d.timeouts[last],
            "{name}: the budget cut is a timeout"
        );
        assert!(d.trajectories().iter().all(|t| t.len() <= 1000), "{name}");
        assert_eq!(
            d.action_log_probs.as_ref().map(|l| l.len()),
            Some(1500),
            "{name}"
        );
        assert!(d.qpos.is_some() && d.qvel.is_some(), "{name}");
        assert_eq!(d.metadata["kind"], name);
        assert_eq!(d.metadata["behaviour_step"], step(level).to_string());
        assert_eq!(d.metadata["behaviour_run_seed"], "0");
        assert!(d.metadata["recipe"].starts_with("D4RL"), "{name}");
    }
    // Same seed and checkpoint: the same bytes; another seed: other episodes.
    assert_eq!(
        std::fs::read(p("medium.hdf5")).unwrap(),
        std::fs::read(p("medium-again.hdf5")).unwrap()
    );
    // The same bytes on another kind of CPU: the policy's arithmetic does not
    // depend on the vector instructions there are (here, capped to none). The
    // fused actor fails this on AVX-512 machines (its register-blocked row
    // kernel adds in another order); AVX2's row loop happens to agree.
    let capped = generate("medium", &p("medium-portable.hdf5"), &small);
    let mut command = std::process::Command::new(env!("CARGO_BIN_EXE_nuno-trainer"));
    command.args(&capped).env("NUNO_SIMD", "portable");
    let output = common::peer::bounded::output_within(&mut command, "dataset generate");
    assert!(output.status.success(), "{output:?}");
    assert_eq!(
        std::fs::read(p("medium.hdf5")).unwrap(),
        std::fs::read(p("medium-portable.hdf5")).unwrap(),
        "NUNO_SIMD=portable generated other bytes"
    );
    assert_ne!(
        read(&p("medium-seed-1.hdf5")).observations,
        medium.observations
    );

    // medium-expert is medium followed by expert.
    let both = read(&p("medium-expert.hdf5"));
    assert_eq!(both.len(), 3000);
    let rows = |d: &Dataset| {
        d.observations
            .outer_iter()
            .map(|r| r.to_vec())
            .collect::<Vec<_>>()
    };
    assert_eq!(rows(&both), [rows(&medium), rows(&expert)].concat());
    assert_eq!(
        both.rewards.to_vec(),
        [medium.rewards.to_vec(), expert.rewards.to_vec()].concat()
    );
    assert_eq!(
        both.timeouts,
        [medium.timeouts.clone(), expert.timeouts.clone()].concat()
    );
    assert_eq!(both.metadata["medium_step"], step("medium").to_string());
    assert_eq!(both.metadata["expert_step"], step("expert").to_string());

    // medium-replay: the run's transitions up to the medium checkpoint, as its
    // interval files hold them.
    ok(&generate(
        "medium-replay",
        &p("medium-replay.hdf5"),
        &["--run", &s(&run)],
    ));
    let replay = read(&p("medium-replay.hdf5"));
    assert_eq!(replay.len(), step("medium"));
    let recorded: Vec<f32> = intervals(&run)
        .iter()
        .take(step("medium") / 300)
        .flat_map(|f| interval(f)["observations"].1.clone())
        .collect();
    assert_eq!(
        replay.observations.iter().copied().collect::<Vec<_>>(),
        recorded
    );
    assert_eq!(replay.metadata["kind"], "medium-replay");

    // What h5py sees.
    let report = inspect("inspect-d4rl", &p("expert.hdf5"), tmp.path());
    assert_eq!(
        report["infos"],
        serde_json::json!(["action_log_probs", "qpos", "qvel"])
    );
    assert_eq!(
        report["shapes"]["infos/action_log_probs"],
        serde_json::json!([1500])
    );
    assert_eq!(report["metadata"]["kind"], "expert");
    assert_eq!(report["continuity_max_error"], 0.0);
    assert_eq!(report["qpos_max_error"], 0.0);

    // NeoRL's low: whole trajectories, root x observed, .npz and .hdf5.
    ok(&generate(
        "low",
        &p("low.npz"),
        &["--layout", "neorl", "--trajectories", "5"],
    ));
    let npz = read_dataset(&p("low.npz"), Some(DatasetFormat::Neorl)).unwrap();
    let hdf5 = read(&p("low.hdf5"));
    assert_eq!(npz.trajectories().len(), 5);
    assert_eq!(npz.obs_dim(), 12);
    assert_eq!(npz.observations, hdf5.observations);
    assert_eq!(npz.terminals, hdf5.terminals);
    let qpos = hdf5.qpos.as_ref().unwrap();
    assert_eq!(
        hdf5.observations.column(0),
        qpos.column(0),
        "root x is observed"
    );
    assert_eq!(hdf5.metadata["policy_observation_layout"], "d4rl");
    assert_eq!(
        hdf5.metadata["behaviour_step"],
        step("neorl-low").to_string()
    );
    let report = inspect("inspect-neorl", &p("low.npz"), tmp.path());
    assert_eq!(
        report["keys"],
        serde_json::json!(["action", "done", "index", "next_obs", "obs", "reward"])
    );
    let n = npz.len();
    assert_eq!(report["shapes"]["obs"], serde_json::json!([n, 12]));
    assert_eq!(report["shapes"]["reward"], serde_json::json!([n, 1]));
    let starts: Vec<usize> = npz.trajectories().iter().map(|t| t.start).collect();
    assert_eq!(report["index"], serde_json::json!(starts));

    // Bad requests, each named before any episode runs.
    let error = fails(&generate("low", &p("x.hdf5"), &[]));
    assert!(error.contains("--layout neorl"), "{error}");
    let error = fails(&generate("expert", &p("x.npz"), &["--layout", "neorl"]));
    assert!(error.contains("D4RL recipe"), "{error}");
    let error = fails(&generate("medium", &p("x.npz"), &[]));
    assert!(error.contains(".hdf5"), "{error}");
    let error = fails(&generate("mediocre", &p("x.hdf5"), &[]));
    assert!(error.contains("mediocre"), "{error}");
    let error = fails(&generate("medium", &p("x.hdf5"), &["--accept-rerun"]));
    assert!(error.contains("medium-replay only"), "{error}");
    let error = fails(&generate("medium-replay", &p("x.hdf5"), &[]));
    assert!(error.contains("--run"), "{error}");
    assert!(
        error.contains(&format!("--seed 0 --steps {}", step("medium"))),
        "the error says how to re-create the run: {error}"
    );
    let other = p("other-run");
    ok(&online::<&str>(&other, 300, 9, &[]));
    let error = fails(&generate(
        "medium-replay",
        &p("x.hdf5"),
        &["--run", &s(&other)],
    ));
    assert!(
        error.contains("not the run the medium policy came from"),
        "{error}"
    );
    // The same configuration, but another policy at the medium step (a re-run
    // under changed arithmetic): its replay is not the medium policy's.
    let diverged = p("diverged-run");
    copy_dir(&run, &diverged);
    let policies = diverged.join("policies");
    let medium_stem = format!("step-{:08}", step("medium"));
    let other_step = if step("medium") == 300 { 600 } else { 300 };
    let other_stem = format!("step-{other_step:08}");
    for ext in ["json", "safetensors"] {
        std::fs::copy(
            policies.join(format!("{other_stem}.{ext}")),
            policies.join(format!("{medium_stem}.{ext}")),
        )
        .unwrap();
    }
    let error = fails(&generate(
        "medium-replay",
        &p("x.hdf5"),
        &["--run", &s(&diverged)],
    ));
    assert!(
        error.contains(&format!(
            "policy at step {} is not the medium policy",
            step("medium")
        )),
        "{error}"
    );
    assert!(error.contains("--accept-rerun"), "{error}");
    // Accepted, it is cut at the same step and says whose policy ends it.
    ok(&generate(
        "medium-replay",
        &p("rerun-replay.hdf5"),
        &["--run", &s(&diverged), "--accept-rerun"],
    ));
    let rerun = read(&p("rerun-replay.hdf5"));
    assert_eq!(rerun.observations, replay.observations);
    assert_eq!(rerun.metadata["medium_policy_reproduced"], "false");
    assert_eq!(replay.metadata["medium_policy_reproduced"], "true");
    let other_policy: serde_json::Value = serde_json::from_slice(
        &std::fs::read(run.join("policies").join(format!("{other_stem}.json"))).unwrap(),
    )
    .unwrap();
    assert_eq!(
        rerun.metadata["behaviour_sha256"],
        other_policy["weights_sha256"].as_str().unwrap()
    );
    assert_eq!(
        rerun.metadata["behaviour_eval_return"],
        format!("{:.3}", other_policy["mean_return"].as_f64().unwrap())
    );
    let mut walker = generate("medium", &p("x.hdf5"), &[]);
    walker[3] = "walker2d".into();
    let error = fails(&walker);
    assert!(
        error.contains("no behaviour policies for walker2d"),
        "{error}"
    );
    // Hopper's policies filed under walker2d are refused by task.
    let misfiled = behaviour.join("walker2d");
    std::fs::create_dir_all(&misfiled).unwrap();
    for entry in std::fs::read_dir(behaviour.join("hopper")).unwrap() {
        let path = entry.unwrap().path();
        std::fs::copy(&path, misfiled.join(path.file_name().unwrap())).unwrap();
    }
    let error = fails(&walker);
    assert!(error.contains("for hopper"), "{error}");
    assert!(!p("x.hdf5").exists() && !p("x.npz").exists());
}
