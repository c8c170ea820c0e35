//! `nuno-trainer fit-policy` and `evaluate --policy` end to end: a tiny run on
//! the shipped model writes policies, metrics and checkpoints, refuses to
//! overwrite a run, resumes to a longer one, and bad flags are named.

mod common;

use std::path::Path;

use common::{copy_dir, fails, generate_hopper, ok, tiny_fit_ensemble, tiny_fit_policy};

#[test]
fn fit_policy_runs_resumes_and_its_policy_evaluates() {
    let tmp = tempfile::tempdir().unwrap();
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/hopper-random");
    let model = tmp.path().join("model");
    copy_dir(&shipped, &model);
    for stale in ["policy.json", "policy.safetensors"] {
        std::fs::remove_file(model.join(stale)).unwrap();
    }
    let dataset = tmp.path().join("hopper.hdf5");
    let run = tmp.path().join("run");
    let (model_s, dataset_s, run_s) = (
        model.to_str().unwrap(),
        dataset.to_str().unwrap(),
        run.to_str().unwrap(),
    );
    generate_hopper(dataset_s, 2000, 0);
    let fit = |steps: usize, extra: &[&str]| -> Vec<String> {
        tiny_fit_policy(
            "nuno",
            &model,
            &dataset,
            Some("hopper-random"),
            steps,
            &run,
            extra,
        )
    };
    let stdout = ok(&fit(20, &[]));
    assert!(stdout.contains("truncation threshold"), "{stdout}");
    for file in [
        "metrics.csv",
        "metrics.jsonl",
        "normalized_score.svg",
        "eta.svg",
        "checkpoints/LATEST",
    ] {
        assert!(run.join(file).is_file(), "{file} missing");
    }
    for file in [
        "policy.json",
        "policy.safetensors",
        "policy-last.json",
        "policy-last.safetensors",
    ] {
        assert!(
            model.join(file).is_file(),
            "{file} missing next to the dynamics"
        );
    }
    let rows = |path: &Path| std::fs::read_to_string(path).unwrap().lines().count() - 1;
    assert_eq!(rows(&run.join("metrics.csv")), 2);

    // run.json holds the resolved plan: Table 3's hopper-random row (h 10,
    // α 1, λ_pen 0.001) under the flags' budget.
    let record = || -> serde_json::Value {
        serde_json::from_slice(&std::fs::read(run.join("run.json")).unwrap()).unwrap()
    };
    let plan = &record()["plan"];
    assert_eq!(plan["method"], "nuno", "{plan}");
    let config = &plan["config"];
    assert_eq!(
        (
            &config["horizon"],
            &config["cvar_alpha"],
            &config["penalty"]
        ),
        (&10.into(), &1.0.into(), &0.001.into()),
        "{config}"
    );
    assert_eq!(config["epochs"], 2, "{config}");

    // A second run into the same directory must not clobber it (nor its record).
    let err = fails(&fit(20, &[]));
    assert!(err.contains("--resume"), "{err}");
    assert_eq!(record()["plan"]["config"]["epochs"], 2);
    // Resuming extends the run: two epochs kept, one more added.
    let stdout = ok(&fit(30, &["--resume"]));
    assert_eq!(record()["plan"]["config"]["epochs"], 3);
    assert!(
        stdout.contains("resumed from") && stdout.contains("epoch 2"),
        "{stdout}"
    );
    assert_eq!(rows(&run.join("metrics.csv")), 3);
    let latest = std::fs::read_to_string(run.join("checkpoints/LATEST")).unwrap();
    assert_eq!(latest.trim(), "epoch-000003");
    let checkpoints = std::fs::read_dir(run.join("checkpoints")).unwrap().count();
    assert_eq!(checkpoints, 2, "LATEST and one checkpoint directory");

    let report = ok(&["evaluate", "--policy", model_s, "--episodes", "2", "--json"]);
    let report: serde_json::Value = serde_json::from_str(&report).unwrap();
    assert_eq!(report["returns"].as_array().unwrap().len(), 2);
    assert!(
        report["mean_normalized_score"]
            .as_f64()
            .unwrap()
            .is_finite()
    );

    // Bad flags and inputs are named.
    let err = fails(&[
        "fit-policy",
        "--model",
        model_s,
        "--dataset",
        dataset_s,
        "--preset",
        "hopper-expert",
        "--out",
        run_s,
    ]);
    assert!(err.contains("unknown preset `hopper-expert`"), "{err}");
    let err = fails(&[
        "fit-policy",
        "--model",
        model_s,
        "--dataset",
        dataset_s,
        "--preset",
        "walker2d-random",
        "--out",
        run_s,
    ]);
    assert!(
        err.contains("preset walker2d-random is for walker2d"),
        "{err}"
    );
    let err = fails(&fit(20, &["--real-ratio", "1.5"]));
    assert!(err.contains("--real-ratio"), "{err}");
    let err = fails(&fit(20, &["--model-buffer-factor", "0"]));
    assert!(err.contains("--model-buffer-factor"), "{err}");
    let err = fails(&fit(20, &["--state-box-margin", "NaN"]));
    assert!(err.contains("--state-box-margin"), "{err}");
    let err = fails(&fit(20, &["--target-entropy", "inf"]));
    assert!(err.contains("--target-entropy must be finite"), "{err}");
    let err = fails(&fit(
        20,
        &["--no-truncation", "--truncated-step", "terminal"],
    ));
    assert!(
        err.contains("--truncated-step") && err.contains("--no-truncation"),
        "{err}"
    );
    let err = fails(&fit(20, &["--truncated-step", "kept"]));
    assert!(err.contains("unknown truncated step \"kept\""), "{err}");
    let err = fails(&fit(20, &["--forward-velocity", "sideways"]));
    assert!(
        err.contains("unknown forward velocity \"sideways\""),
        "{err}"
    );
    // hopper-random's observations hold no root x: a reward read from it is refused.
    let err = fails(&fit(20, &["--root-x-reward", "velocity"]));
    assert!(
        err.contains(
            "--root-x-reward velocity changes the reward on observations that hold root x"
        ),
        "{err}"
    );
    let err = fails(&["evaluate", "--policy", dataset_s, "--episodes", "1"]);
    assert!(err.contains("loading policy"), "{err}");
}

/// COMBO trains in MOPO's ensemble with its own row (h 5, β 5 on
/// hopper-medium), no penalty, half the batch real, the conservative term on;
/// a dataset without a COMBO row is refused by name.
#[test]
fn combo_trains_in_the_ensemble_with_the_conservative_term() {
    let tmp = tempfile::tempdir().unwrap();
    let (dataset, model, run) = (
        tmp.path().join("hopper.hdf5"),
        tmp.path().join("ensemble"),
        tmp.path().join("run"),
    );
    generate_hopper(dataset.to_str().unwrap(), 1500, 0);
    tiny_fit_ensemble(&dataset, &model);
    let fit = |preset: &str, extra: &[&str]| {
        tiny_fit_policy("combo", &model, &dataset, Some(preset), 20, &run, extra)
    };
    ok(&fit("hopper-medium", &[]));
    let record: serde_json::Value =
        serde_json::from_slice(&std::fs::read(run.join("run.json")).unwrap()).unwrap();
    let config = &record["plan"]["config"];
    assert_eq!(config["horizon"], 5, "{config}");
    assert_eq!(config["conservative"]["cql_weight"], 5.0, "{config}");
    assert_eq!(
        (&config["penalty"], &config["real_ratio"]),
        (&0.0.into(), &0.5.into())
    );
    assert_eq!(config["truncate"], false, "{config}");
    let records = std::fs::read_to_string(run.join("metrics.jsonl")).unwrap();
    for line in records.lines() {
        let r: serde_json::Value = serde_json::from_str(line).unwrap();
        let f = |k: &str| r["rollout"][k].as_f64().unwrap();
        assert_eq!(
            f("mean_penalized_reward"),
            f("mean_reward"),
            "no penalty: {r}"
        );
    }
    let err = fails(&fit("hopper-random", &["--resume"]));
    assert!(err.contains("hopper-random (for COMBO's h and β)"), "{err}");
    let err = fails(&tiny_fit_policy(
        "mopo",
        &model,
        &dataset,
        Some("hopper-medium"),
        20,
        &run,
        &["--combo-weight", "1"],
    ));
    assert!(err.contains("--combo-weight is COMBO's"), "{err}");
}

/// MOReL trains in MOPO's ensemble as a pessimistic MDP: MOPO's h, no
/// penalty, a HALT at 3 × the largest pairwise discrepancy on the dataset
/// (kept in threshold.json), κ from --halt-penalty. MOPO's rows, which MOReL
/// reads its h from, stop at D4RL: on NeoRL both --horizon and --penalty stand in.
#[test]
fn morel_halts_where_the_members_disagree() {
    let tmp = tempfile::tempdir().unwrap();
    let (dataset, model, run) = (
        tmp.path().join("hopper.hdf5"),
        tmp.path().join("ensemble"),
        tmp.path().join("run"),
    );
    generate_hopper(dataset.to_str().unwrap(), 1500, 0);
    tiny_fit_ensemble(&dataset, &model);
    let fit = |extra: &[&str]| {
        tiny_fit_policy(
            "morel",
            &model,
            &dataset,
            Some("hopper-medium"),
            20,
            &run,
            extra,
        )
    };
    ok(&fit(&["--halt-penalty", "2"]));
    let record: serde_json::Value =
        serde_json::from_slice(&std::fs::read(run.join("run.json")).unwrap()).unwrap();
    let plan = &record["plan"];
    assert_eq!(plan["pessimism"], 3.0, "{plan}");
    let config = &plan["config"];
    assert_eq!(
        (&config["horizon"], &config["penalty"]),
        (&5.into(), &0.0.into())
    );
    assert_eq!(config["halt_penalty"], 2.0, "{config}");
    let threshold: serde_json::Value =
        serde_json::from_slice(&std::fs::read(run.join("threshold.json")).unwrap()).unwrap();
    assert!(
        threshold["how"].as_str().unwrap().contains("MOReL's HALT"),
        "{threshold}"
    );
    assert!(threshold["threshold"].as_f64().unwrap() > 0.0);
    let err = fails(&tiny_fit_policy(
        "mopo",
        &model,
        &dataset,
        Some("hopper-medium"),
        20,
        &run,
        &["--halt-penalty", "1"],
    ));
    assert!(err.contains("--halt-penalty is MOReL's"), "{err}");
    // MOPO's table has no NeoRL rows: --horizon and --penalty stand in, one alone does not.
    let neorl = |extra: &[&str]| {
        let preset = Some("neorl-hopper-low");
        tiny_fit_policy("mopo", &model, &dataset, preset, 20, &run, extra)
    };
    let err = fails(&neorl(&["--horizon", "3", "--resume"]));
    assert!(err.contains("neorl-hopper-low (for MOPO)"), "{err}");
    let err = fails(&neorl(&["--horizon", "3", "--penalty", "1", "--resume"]));
    assert!(
        err.contains("preset neorl-hopper-low is for hopper"),
        "past MOPO's table, to the model's check: {err}"
    );
}

#[test]
fn mopo_trains_in_the_ensemble_with_its_penalty_and_no_truncation() {
    let tmp = tempfile::tempdir().unwrap();
    let (dataset, model, run) = (
        tmp.path().join("hopper.hdf5"),
        tmp.path().join("ensemble"),
        tmp.path().join("run"),
    );
    let s = |p: &Path| p.to_str().unwrap().to_string();
    generate_hopper(&s(&dataset), 1500, 0);
    tiny_fit_ensemble(&dataset, &model);
    ok(&tiny_fit_policy(
        "mopo",
        &model,
        &dataset,
        Some("hopper-medium"),
        20,
        &run,
        &[
            "--target-entropy",
            "-2.5",
            "--clip-observations",
            "--rollout-noise-scale",
            "0.25",
        ],
    ));
    // MOPO's hopper-medium row: h = 5, λ = 5; never truncated; r̃ = r − λ·max‖σ‖.
    let records: Vec<serde_json::Value> = std::fs::read_to_string(run.join("metrics.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(records.len(), 2);
    for r in &records {
        let rollout = &r["rollout"];
        assert_eq!(rollout["truncated"], 0);
        let f = |k: &str| rollout[k].as_f64().unwrap();
        assert!(f("mean_length") <= 5.0, "{rollout}");
        let expected = f("mean_reward") - 5.0 * f("mean_eta");
        assert!(
            (f("mean_penalized_reward") - expected).abs() < 1e-3 * expected.abs().max(1.0),
            "{rollout}"
        );
        assert!(f("mean_eta") > 0.0);
    }
    let policy: serde_json::Value =
        serde_json::from_slice(&std::fs::read(model.join("policy.json")).unwrap()).unwrap();
    let ensemble: serde_json::Value =
        serde_json::from_slice(&std::fs::read(model.join("ensemble.json")).unwrap()).unwrap();
    assert_eq!(policy["dynamics_sha256"], ensemble["weights_sha256"]);
    assert_eq!(policy["training"]["penalty"], 5.0);
    assert_eq!(policy["training"]["truncate"], false);
    // OfflineRL-Kit's MOPO by default.
    let training = &policy["training"];
    assert_kit_sac_settings(training);
    // The loop's switches as given: SAC's target entropy, the task's observation
    // clip, the rollouts' noise scale.
    assert_eq!(training["sac"]["target_entropy"], -2.5);
    assert_eq!(training["clip_observations"], true);
    assert_eq!(training["rollout_noise_scale"], 0.25);
    // TATU+MOPO on the same ensemble: MOPO's penalty, truncation at the
    // largest disagreement on the dataset / pessimism, kept for a resume.
    let tatu = |out: &Path, steps: usize, extra: &[&str]| {
        ok(&tiny_fit_policy(
            "tatu-mopo",
            &model,
            &dataset,
            Some("hopper-medium"),
            steps,
            out,
            extra,
        ))
    };
    let saved = |out: &Path| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(out.join("threshold.json")).unwrap()).unwrap()
    };
    let (lax, strict) = (tmp.path().join("tatu-1"), tmp.path().join("tatu-50"));
    tatu(&lax, 20, &["--pessimism", "1"]);
    // NUNO's and TATU's code's form of the truncating step: kept as terminal.
    let strict_flags = ["--pessimism", "50", "--truncated-step", "terminal"];
    tatu(&strict, 20, &strict_flags);
    let threshold = |out: &Path| saved(out)["threshold"].as_f64().unwrap();
    assert_eq!(saved(&lax)["algorithm"], "tatu-mopo");
    assert!(threshold(&lax) > 0.0);
    assert!((threshold(&strict) * 50.0 / threshold(&lax) - 1.0).abs() < 1e-5);
    let policy: serde_json::Value =
        serde_json::from_slice(&std::fs::read(model.join("policy.json")).unwrap()).unwrap();
    assert_eq!(policy["algorithm"], "tatu-mopo");
    assert!((policy["truncation_threshold"].as_f64().unwrap() - threshold(&strict)).abs() < 1e-6);
    assert_eq!(policy["training"]["penalty"], 5.0);
    assert_eq!(policy["training"]["truncate"], true);
    assert_eq!(policy["training"]["truncated_step"], "terminal");
    let rollouts = |out: &Path| -> Vec<serde_json::Value> {
        std::fs::read_to_string(out.join("metrics.jsonl"))
            .unwrap()
            .lines()
            .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap()["rollout"].clone())
            .collect()
    };
    // A fiftieth of the largest one-step disagreement is passed within h = 5
    // by nearly every rollout; the whole of it by fewer.
    let truncated = |out: &Path| -> u64 {
        rollouts(out)
            .iter()
            .map(|r| r["truncated"].as_u64().unwrap())
            .sum()
    };
    assert!(
        truncated(&strict) > truncated(&lax),
        "{} vs {}",
        truncated(&strict),
        truncated(&lax)
    );
    // A resumed run truncates where it did (its checkpoint holds ε; the
    // dataset pass is not repeated).
    let stdout = tatu(&strict, 30, &[&strict_flags[..], &["--resume"]].concat());
    let printed = format!("truncation threshold {:.4}", threshold(&strict));
    assert!(stdout.contains(&printed), "{stdout}");
    // MOPO on its ensemble with `extra` flags, which it refuses before writing.
    let (model_s, dataset_s, out) = (s(&model), s(&dataset), s(&tmp.path().join("x")));
    let mopo_fails = |extra: &[&str]| {
        let mut args = vec![
            "fit-policy",
            "--algo",
            "mopo",
            "--model",
            &model_s,
            "--dataset",
            &dataset_s,
            "--preset",
            "hopper-medium",
            "--out",
            &out,
        ];
        args.extend(extra);
        fails(&args)
    };
    let error = mopo_fails(&["--pessimism", "2"]);
    assert!(error.contains("--pessimism"), "{error}");
    // MOPO never truncates, so it keeps no truncating step either way.
    let error = mopo_fails(&["--truncated-step", "terminal"]);
    assert!(
        error.contains("--truncated-step says what a truncating rollout keeps")
            && error.contains("mopo never truncates"),
        "{error}"
    );
    // NUNO's code's loop settings are refused for MOPO's ensemble, by name.
    for extra in [
        ["--recipe", "code"],
        ["--forward-velocity", "mean"],
        ["--root-x-reward", "velocity"],
    ] {
        let error = mopo_fails(&extra);
        assert!(
            error.contains(extra[0]) && error.contains("ensemble"),
            "{error}"
        );
    }
    // A method that does not exist is refused with the list of those that do.
    let error = fails(&[
        "fit-policy",
        "--algo",
        "mbpo",
        "--model",
        &model_s,
        "--dataset",
        &dataset_s,
        "--preset",
        "hopper-medium",
        "--out",
        &out,
    ]);
    assert!(
        error.contains("mbpo") && error.contains("nuno-al") && error.contains("tatu-mopo"),
        "{error}"
    );
    // The neural SDE's run needs its own model. Refused after claiming its
    // --out, it leaves nothing there: no folder it made, an empty one it found.
    let (made, found) = (tmp.path().join("other"), tmp.path().join("found"));
    std::fs::create_dir(&found).unwrap();
    for out in [&made, &found] {
        let error = fails(&[
            "fit-policy",
            "--model",
            &s(&model),
            "--dataset",
            &s(&dataset),
            "--preset",
            "hopper-medium",
            "--steps",
            "10",
            "--out",
            &s(out),
        ]);
        assert!(error.contains("model.json"), "{error}");
    }
    assert!(!made.exists(), "the refused run left the --out it made");
    let left: Vec<_> = std::fs::read_dir(&found).unwrap().collect();
    assert!(left.is_empty(), "the refused run left {left:?}");
}

#[test]
fn nuno_al_penalises_and_truncates_on_the_aleatoric_sigma() {
    let tmp = tempfile::tempdir().unwrap();
    let shipped = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/hopper-random");
    let (model, dataset, run) = (
        tmp.path().join("model"),
        tmp.path().join("hopper.hdf5"),
        tmp.path().join("run"),
    );
    copy_dir(&shipped, &model);
    let s = |p: &Path| p.to_str().unwrap().to_string();
    generate_hopper(&s(&dataset), 2000, 0);
    let args = |algo: &str, out: &Path, extra: &[&str]| -> Vec<String> {
        tiny_fit_policy(
            algo,
            &model,
            &dataset,
            Some("hopper-medium"),
            10,
            out,
            extra,
        )
    };
    ok(&args("nuno-al", &run, &[]));
    let saved: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("threshold.json")).unwrap())
            .unwrap();
    assert_eq!(saved["algorithm"], "nuno-al");
    assert!(saved["how"].as_str().unwrap().contains("‖σ‖"), "{saved}");
    // The uncertainty the run penalised is ‖σ‖, not η: its rollouts' mean is
    // of the SDE's σ scale (larger off the data the rollouts wander into, so
    // a loose band) and differs from NUNO's η on the same model.
    let nuno_run = tmp.path().join("nuno");
    ok(&args(
        "nuno",
        &nuno_run,
        &["--mopo-settings", "offlinerl-kit"],
    ));
    let mean_eta = |out: &Path| -> f64 {
        let text = std::fs::read_to_string(out.join("metrics.jsonl")).unwrap();
        let record: serde_json::Value = serde_json::from_str(text.lines().next().unwrap()).unwrap();
        record["rollout"]["mean_eta"].as_f64().unwrap()
    };
    let sigma = model_sigma_norm(&model, &dataset);
    assert!(
        (0.5..3.0).contains(&(mean_eta(&run) / sigma)),
        "NUNO^al's uncertainty {} vs the model's ‖σ‖ on the data {sigma}",
        mean_eta(&run)
    );
    assert!(
        (mean_eta(&nuno_run) - mean_eta(&run)).abs() > 0.1 * sigma,
        "NUNO's η {} should differ from ‖σ‖ {}",
        mean_eta(&nuno_run),
        mean_eta(&run)
    );
    let policy: serde_json::Value =
        serde_json::from_slice(&std::fs::read(model.join("policy.json")).unwrap()).unwrap();
    assert_eq!(policy["algorithm"], "nuno");
    // NUNO's loop on MOPO's SAC settings where asked (NUNO's own: 3e-4, constant).
    assert_kit_sac_settings(&policy["training"]);
    // nuno-r needs a model that learned the reward; the shipped one did not.
    let error = fails(
        &args("nuno-r", &tmp.path().join("r"), &[])
            .iter()
            .map(String::as_str)
            .collect::<Vec<_>>(),
    );
    assert!(error.contains("--reward-model"), "{error}");
}

/// A policy record's training on OfflineRL-Kit's MOPO settings: actor and α
/// at 1e-4, the actor cosine-annealed, the tests' --rollout-batch (32) kept
/// over the settings' 50 000.
fn assert_kit_sac_settings(training: &serde_json::Value) {
    assert_eq!(
        (&training["sac"]["actor_lr"], &training["sac"]["alpha_lr"]),
        (&serde_json::json!(1e-4), &serde_json::json!(1e-4)),
        "{training}"
    );
    assert_eq!(training["actor_lr_decay"], "cosine");
    assert_eq!(training["rollout_batch"], 32);
}

/// Mean ‖σ(s, a)‖₂ of the model in `dir` over the first 500 of the dataset's
/// transitions, through the library's burn path.
fn model_sigma_norm(dir: &Path, dataset: &Path) -> f64 {
    use nuno::shared::BatchDynamics;
    let device = burn::tensor::Device::flex();
    let (sde, _) = nuno::artifact::load_dynamics(dir, &device).unwrap();
    let data = nuno::data::read_dataset(dataset, None).unwrap();
    let n = 500;
    let states: Vec<f32> = data
        .observations
        .rows()
        .into_iter()
        .take(n)
        .flatten()
        .copied()
        .collect();
    let actions: Vec<f32> = data
        .actions
        .rows()
        .into_iter()
        .take(n)
        .flatten()
        .copied()
        .collect();
    let step = BatchDynamics::step(&sde, &states, &actions, &vec![0.0; states.len()]);
    let d = data.obs_dim();
    step.sigma
        .chunks_exact(d)
        .map(|s| f64::from(s.iter().map(|x| x * x).sum::<f32>()).sqrt())
        .sum::<f64>()
        / n as f64
}

/// bc and td3-bc learn from the dataset alone: no --model, the policies in
/// --out with their method and settings, evaluable; the model-based flags and
/// a missing model are named.
#[test]
fn model_free_methods_train_on_the_dataset_alone() {
    let tmp = tempfile::tempdir().unwrap();
    let dataset = tmp.path().join("hopper.hdf5");
    let dataset_s = dataset.to_str().unwrap();
    generate_hopper(dataset_s, 2000, 0);
    let fit = |algo: &str, out: &str, extra: &[&str]| -> Vec<String> {
        let run = tmp.path().join(out);
        let mut args: Vec<String> = [
            "fit-policy",
            "--algo",
            algo,
            "--dataset",
            dataset_s,
            "--preset",
            "hopper-random",
            "--steps",
            "20",
            "--steps-per-epoch",
            "10",
            "--batch-size",
            "32",
            "--hidden",
            "16,16",
            "--eval-episodes",
            "1",
            "--out",
            run.to_str().unwrap(),
        ]
        .map(String::from)
        .to_vec();
        args.extend(extra.iter().map(|e| e.to_string()));
        args
    };
    for algo in ["bc", "td3-bc", "cql", "edac"] {
        // OfflineRL-Kit gives EDAC no critics or η for the random datasets.
        let edac = ["--edac-critics", "3", "--edac-eta", "1"];
        ok(&fit(algo, algo, if algo == "edac" { &edac } else { &[] }));
        let run = tmp.path().join(algo);
        let policy: serde_json::Value =
            serde_json::from_slice(&std::fs::read(run.join("policy.json")).unwrap()).unwrap();
        assert_eq!(policy["algorithm"], algo, "{policy}");
        assert_eq!(policy["model_free_training"]["epochs"], 2, "{policy}");
        assert!(policy["training"].is_null(), "{policy}");
        let record: serde_json::Value =
            serde_json::from_slice(&std::fs::read(run.join("run.json")).unwrap()).unwrap();
        assert_eq!(record["plan"]["task"], "hopper", "{record}");
        let rows = std::fs::read_to_string(run.join("metrics.csv")).unwrap();
        assert_eq!(rows.lines().count(), 3, "{rows}");
        let report = ok(&[
            "evaluate",
            "--policy",
            run.to_str().unwrap(),
            "--episodes",
            "1",
            "--json",
        ]);
        let report: serde_json::Value = serde_json::from_str(&report).unwrap();
        assert_eq!(report["returns"].as_array().unwrap().len(), 1);
    }
    let td3: serde_json::Value =
        serde_json::from_slice(&std::fs::read(tmp.path().join("td3-bc/policy.json")).unwrap())
            .unwrap();
    let learner = &td3["model_free_training"]["learner"];
    assert_eq!(
        (&learner["alpha"], &learner["policy_freq"]),
        (&2.5.into(), &2.into()),
        "{learner}"
    );

    let err = fails(&fit("bc", "bad", &["--model", dataset_s]));
    assert!(
        err.contains("--algo bc learns from the dataset alone: --model"),
        "{err}"
    );
    let err = fails(&fit("td3-bc", "bad", &["--horizon", "5"]));
    assert!(
        err.contains("--horizon is for the model-based methods"),
        "{err}"
    );
    let err = fails(&fit("cql", "bad", &["--mopo-settings", "nuno"]));
    assert!(
        err.contains("--mopo-settings sets the SAC settings") && err.contains("cql runs its own"),
        "{err}"
    );
    let err = fails(&fit("cql", "bad", &["--rollout-noise-scale", "0"]));
    assert!(
        err.contains("--rollout-noise-scale is for the model-based methods"),
        "{err}"
    );
    let err = fails(&fit("cql", "bad", &["--root-x-reward", "difference"]));
    assert!(
        err.contains("--root-x-reward is for the model-based methods"),
        "{err}"
    );
    let err = fails(&fit("cql", "bad", &["--clip-observations"]));
    assert!(
        err.contains("--clip-observations is for the model-based methods"),
        "{err}"
    );
    let err = fails(&fit("td3-bc", "bad", &["--task", "walker2d"]));
    assert!(
        err.contains("--task walker2d and the preset hopper-random"),
        "{err}"
    );
    let err = fails(&fit("edac", "bad", &[]));
    assert!(
        err.contains("unknown preset `hopper-random (for EDAC's critics and η)`"),
        "{err}"
    );
    let err = fails(&fit("bc", "bad", &["--edac-eta", "2"]));
    assert!(err.contains("--edac-eta are EDAC's"), "{err}");
    let err = fails(&fit("mopo", "bad", &[]));
    assert!(
        err.contains("--algo mopo trains in a model: give --model"),
        "{err}"
    );
}

/// MOBILE trains in MOPO's ensemble with its own row (hopper-medium: h 5, β
/// 1.5, α fixed at 0.2), no penalty at rollout time and no truncation, a
/// deterministic backup floored at 0, and every epoch records the Bellman
/// inconsistency its updates subtracted; a model without an ensemble, and the
/// flag without the method, are refused by name.
#[test]
fn mobile_penalises_updates_by_the_elites_bellman_inconsistency() {
    let tmp = tempfile::tempdir().unwrap();
    let (dataset, model, run) = (
        tmp.path().join("hopper.hdf5"),
        tmp.path().join("ensemble"),
        tmp.path().join("run"),
    );
    generate_hopper(dataset.to_str().unwrap(), 1500, 0);
    tiny_fit_ensemble(&dataset, &model);
    let fit = |algo: &str, preset: &str, extra: &[&str]| {
        tiny_fit_policy(algo, &model, &dataset, Some(preset), 20, &run, extra)
    };
    ok(&fit("mobile", "hopper-medium", &[]));
    let record: serde_json::Value =
        serde_json::from_slice(&std::fs::read(run.join("run.json")).unwrap()).unwrap();
    let config = &record["plan"]["config"];
    assert_eq!(config["horizon"], 5, "{config}");
    assert_eq!(config["bellman_penalty"]["beta"], 1.5, "{config}");
    assert_eq!(
        (&config["penalty"], &config["truncate"]),
        (&0.0.into(), &false.into())
    );
    let sac = &config["sac"];
    assert_eq!(
        (&sac["backup"]["deterministic"], &sac["backup"]["floor"]),
        (&true.into(), &0.0.into())
    );
    assert_eq!(
        (&sac["initial_alpha"], &sac["alpha_lr"]),
        (&0.2.into(), &0.0.into())
    );
    let records = std::fs::read_to_string(run.join("metrics.jsonl")).unwrap();
    for line in records.lines() {
        let r: serde_json::Value = serde_json::from_str(line).unwrap();
        assert!(r["bellman_penalty"].as_f64().unwrap() > 0.0, "{r}");
        assert!(
            (r["losses"]["alpha"].as_f64().unwrap() - 0.2).abs() < 1e-6,
            "{r}"
        );
    }
    let err = fails(&fit("mobile", "neorl-hopper-low", &["--resume"]));
    assert!(
        err.contains("neorl-hopper-low (for MOBILE's h and β)"),
        "{err}"
    );
    let err = fails(&fit("mopo", "hopper-medium", &["--mobile-penalty", "1"]));
    assert!(err.contains("--mobile-penalty is MOBILE's"), "{err}");
}

/// RAMBO trains in MOPO's ensemble with its own row (hopper-medium: h 5,
/// w_adv 3e-4), no penalty and no truncation, half the batch real, rollouts
/// every 250 steps; its adversary's phase runs at the first step (losses in
/// metrics.jsonl), `--adversary-steps` model steps in all, and its checkpoint
/// carries the adversarial ensemble, so a
/// resumed run goes on from it; its flags without the method are refused.
#[test]
fn rambo_trains_its_adversary_and_resumes_with_it() {
    let tmp = tempfile::tempdir().unwrap();
    let (dataset, model, run) = (
        tmp.path().join("hopper.hdf5"),
        tmp.path().join("ensemble"),
        tmp.path().join("run"),
    );
    generate_hopper(dataset.to_str().unwrap(), 1500, 0);
    tiny_fit_ensemble(&dataset, &model);
    let small = ["--adversary-steps", "3", "--bc-epochs", "2"];
    let fit = |algo: &str, steps: usize, extra: &[&str]| {
        tiny_fit_policy(
            algo,
            &model,
            &dataset,
            Some("hopper-medium"),
            steps,
            &run,
            extra,
        )
    };
    ok(&fit("rambo", 10, &small));
    let record: serde_json::Value =
        serde_json::from_slice(&std::fs::read(run.join("run.json")).unwrap()).unwrap();
    let config = &record["plan"]["config"];
    assert_eq!(config["horizon"], 5, "{config}");
    assert_eq!(config["rambo"]["adversary"]["adv_weight"], 3e-4, "{config}");
    assert_eq!(config["rambo"]["adversary_steps"], 3, "{config}");
    assert_eq!(
        (&config["penalty"], &config["truncate"]),
        (&0.0.into(), &false.into())
    );
    assert_eq!(config["real_ratio"], 0.5, "{config}");
    let first = std::fs::read_to_string(run.join("metrics.jsonl")).unwrap();
    let r: serde_json::Value = serde_json::from_str(first.lines().next().unwrap()).unwrap();
    assert!(
        r["adversary"]["supervised"].as_f64().unwrap().is_finite(),
        "{r}"
    );
    let checkpoints = run.join("checkpoints");
    let latest = std::fs::read_to_string(checkpoints.join("LATEST")).unwrap();
    assert!(
        checkpoints
            .join(latest.trim())
            .join("adversary.safetensors")
            .is_file()
    );
    // One phase of --adversary-steps 3 model steps in all (chains of up to h = 5
    // count each step, as OfflineRL-Kit's), so the adversary's Adam stepped 3 times.
    let state: serde_json::Value = serde_json::from_slice(
        &std::fs::read(checkpoints.join(latest.trim()).join("state.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(state["adversary"]["adam_time"], 3, "{}", state["adversary"]);
    let out = ok(&fit("rambo", 20, &[&small[..], &["--resume"]].concat()));
    assert!(out.contains("resumed from"), "{out}");
    let err = fails(&fit("mopo", 10, &["--rambo-weight", "1"]));
    assert!(
        err.contains("--rambo-weight, --adversary-steps and --bc-epochs are RAMBO's"),
        "{err}"
    );
}
