//! `nuno-trainer experiment` end to end on a tiny grid: bad grids are refused
//! by name before anything runs; a local run finishes every cell, reruns
//! nothing, resumes a killed cell; the report's table is the mean ± std of
//! the cells' own metrics; the Slurm executor submits one array job to a real
//! single-node Slurm (deploy/slurm/local-cluster.sh) and its cells finish.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

use common::{fails, generate_hopper, ok};

/// A budget of `policy_steps` gradient steps in epochs of 10, tiny networks.
fn budget(policy_steps: usize) -> String {
    format!(
        "[budget]\nmodel_steps = 20\nensemble_max_epochs = 2\npolicy_steps = {policy_steps}\nsteps_per_epoch = 10\n\
         eval_episodes = 1\nrollout_batch = 32\nhidden = [16, 16]\n"
    )
}

fn dataset_row(
    name: &str,
    file: &str,
    task: &str,
    preset: &str,
    methods: &str,
    seeds: &str,
) -> String {
    format!(
        "\n[[datasets]]\nname = \"{name}\"\nfile = \"{file}\"\ntask = \"{task}\"\npreset = \"{preset}\"\nmethods = {methods}\nseeds = {seeds}\n"
    )
}

fn write_grid(dir: &Path, name: &str, rows: &[String]) -> PathBuf {
    write_grid_with(dir, name, 20, rows)
}

fn write_grid_with(dir: &Path, name: &str, policy_steps: usize, rows: &[String]) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, format!("{}{}", budget(policy_steps), rows.concat())).unwrap();
    path
}

/// A 2000-transition hopper-random file and a grid over it with `methods` and `seeds`.
fn hopper_grid(dir: &Path, methods: &str, seeds: &str) -> String {
    generate_hopper(&s(&dir.join("hopper.hdf5")), 2000, 0);
    let row = dataset_row(
        "hopper-random",
        "hopper.hdf5",
        "hopper",
        "hopper-random",
        methods,
        seeds,
    );
    s(&write_grid(dir, "grid.toml", &[row]))
}

/// Adds `line` to the grid file's `[budget]` table.
fn add_to_budget(grid: &Path, line: &str) {
    let text = std::fs::read_to_string(grid).unwrap();
    std::fs::write(
        grid,
        text.replace("[budget]\n", &format!("[budget]\n{line}\n")),
    )
    .unwrap();
}

fn s(p: &Path) -> String {
    p.to_str().unwrap().to_string()
}

/// Each epoch's normalised score from a cell's fit-policy metrics.jsonl.
fn scores(cell: &Path) -> Vec<f64> {
    std::fs::read_to_string(cell.join("policy/metrics.jsonl"))
        .unwrap()
        .lines()
        .map(|l| {
            let v: serde_json::Value = serde_json::from_str(l).unwrap();
            v["eval"]["normalized_score"].as_f64().unwrap()
        })
        .collect()
}

#[test]
fn bad_grids_are_refused_before_anything_runs() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    generate_hopper(&s(&dir.join("hopper.hdf5")), 300, 0);
    let out = s(&dir.join("out"));
    let cases = [
        (
            dataset_row(
                "h",
                "hopper.hdf5",
                "hopper",
                "hopper-random",
                "[\"nuno\", \"dreamer\"]",
                "[0]",
            ),
            "unknown method `dreamer`",
        ),
        (
            dataset_row(
                "h",
                "hopper.hdf5",
                "hopper",
                "hopper-randomish",
                "[\"nuno\"]",
                "[0]",
            ),
            "hopper-randomish",
        ),
        (
            dataset_row(
                "h",
                "missing.hdf5",
                "hopper",
                "hopper-random",
                "[\"nuno\"]",
                "[0]",
            ),
            "does not exist",
        ),
        (
            dataset_row(
                "h",
                "hopper.hdf5",
                "walker2d",
                "hopper-random",
                "[\"nuno\"]",
                "[0]",
            ),
            "its preset `hopper-random` is for hopper",
        ),
        (
            dataset_row(
                "h",
                "hopper.hdf5",
                "walker2d",
                "walker2d-random",
                "[\"nuno\"]",
                "[0]",
            ),
            "does not fit walker2d",
        ),
        (
            dataset_row(
                "h",
                "hopper.hdf5",
                "hopper",
                "neorl-hopper-low",
                "[\"mopo\"]",
                "[0]",
            ),
            "mopo needs its own row: unknown preset `neorl-hopper-low (for MOPO)`",
        ),
        (
            dataset_row(
                "h",
                "hopper.hdf5",
                "hopper",
                "neorl-hopper-low",
                "[\"nuno\", \"tatu-mopo\"]",
                "[0]",
            ),
            "tatu-mopo needs its own row: unknown preset `neorl-hopper-low (for MOPO)`",
        ),
        (
            dataset_row(
                "h",
                "hopper.hdf5",
                "hopper",
                "hopper-random",
                "[\"bc\", \"combo\"]",
                "[0]",
            ),
            "combo needs its own row: unknown preset `hopper-random (for COMBO's h and β)`",
        ),
        (
            dataset_row(
                "h",
                "hopper.hdf5",
                "hopper",
                "hopper-random",
                "[\"nuno\"]",
                "[0, 0]",
            ),
            "appears twice",
        ),
        (
            format!(
                "{}{}",
                dataset_row(
                    "h",
                    "hopper.hdf5",
                    "hopper",
                    "hopper-random",
                    "[\"nuno\"]",
                    "[0]"
                ),
                "colour = \"red\"\n"
            ),
            "colour",
        ),
    ];
    for (i, (row, expected)) in cases.iter().enumerate() {
        let grid = s(&write_grid(
            dir,
            &format!("grid-{i}.toml"),
            std::slice::from_ref(row),
        ));
        let error = fails(&["experiment", "run", "--grid", &grid, "--out", &out]);
        assert!(error.contains(expected), "case {i}: {error}");
    }
    assert!(!dir.join("out").exists(), "nothing ran");

    let good_row = dataset_row(
        "h",
        "hopper.hdf5",
        "hopper",
        "hopper-random",
        "[\"nuno\"]",
        "[0]",
    );
    // A model option the fit does not have.
    let grid = write_grid(dir, "grid-likelihood.toml", std::slice::from_ref(&good_row));
    add_to_budget(&grid, "model_likelihood = \"exact\"");
    let error = fails(&["experiment", "run", "--grid", &s(&grid), "--out", &out]);
    assert!(
        error.contains("exact") && error.contains("model_likelihood"),
        "{error}"
    );
    assert!(!dir.join("out").exists(), "nothing ran");
    for (i, (line, named)) in [
        ("recipe = \"codes\"", "recipe"),
        ("forward_velocity = \"sideways\"", "forward_velocity"),
        ("root_x_reward = \"sideways\"", "root_x_reward"),
        (
            "root_x_reward = \"velocity\"",
            "dataset `h`: budget root_x_reward = \"velocity\" changes the reward on observations that hold root x",
        ),
        ("model_buffer_factor = 0", "model_buffer_factor = 0"),
        ("model_sample_noise = \"loud\"", "model_sample_noise"),
        ("model_step_discount = 0.0", "model_step_discount = 0"),
        ("model_eta_losses = \"codes\"", "model_eta_losses"),
        ("threshold_max_margin = 0.9", "threshold_max_margin = 0.9"),
        ("model_drift_inputs = \"angles\"", "model_drift_inputs"),
        ("state_box_margin = -0.5", "state_box_margin = -0.5"),
        ("target_entropy = nan", "target_entropy = NaN"),
        (
            "penalty = -1.0",
            "penalty = -1 must be finite and at least 0",
        ),
    ]
    .into_iter()
    .enumerate()
    {
        let grid = write_grid(
            dir,
            &format!("grid-recipe-{i}.toml"),
            std::slice::from_ref(&good_row),
        );
        add_to_budget(&grid, line);
        let error = fails(&["experiment", "run", "--grid", &s(&grid), "--out", &out]);
        assert!(error.contains(named), "{line}: {error}");
        assert!(!dir.join("out").exists(), "nothing ran");
    }

    // --executor slurm without Slurm's client.
    let grid = s(&write_grid(dir, "grid.toml", &[good_row]));
    let mut command = Command::new(env!("CARGO_BIN_EXE_nuno-trainer"));
    command
        .args([
            "experiment",
            "run",
            "--grid",
            &grid,
            "--out",
            &out,
            "--executor",
            "slurm",
        ])
        .env("PATH", "/nonexistent");
    let output = common::peer::bounded::output_within(&mut command, "nuno-trainer experiment run");
    assert!(!output.status.success());
    let error = String::from_utf8_lossy(&output.stderr);
    assert!(error.contains("needs `sbatch` on PATH"), "{error}");
    assert!(!dir.join("out/slurm").exists(), "nothing was submitted");
}

/// A grid over a 300-transition hopper file: dataset `a` (nuno and mopo,
/// seeds 0 and 1) on it, dataset `b` (nuno, seed 7) on `b_file`.
/// A rebuild replaces the binary under a running sweep (cargo unlinks the old
/// file): the runner still starts its cells, and each records its build, through
/// `/proc/self/exe`, where the path it was started from names a deleted file.
#[test]
#[cfg(target_os = "linux")]
fn a_sweep_outlives_a_rebuild_that_replaces_its_binary() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let grid = hopper_grid(dir, "[\"bc\"]", "[0]");
    let binary = dir.join("nuno-trainer");
    std::fs::copy(env!("CARGO_BIN_EXE_nuno-trainer"), &binary).unwrap();
    let log = std::fs::File::create(dir.join("runner.log")).unwrap();
    let mut runner = Command::new(&binary)
        .args(["experiment", "run", "--grid", &grid, "--out"])
        .arg(dir.join("out"))
        .stdout(log.try_clone().unwrap())
        .stderr(log)
        .spawn()
        .unwrap();
    // Spawning returns once the runner runs the binary, so the file can go.
    std::fs::remove_file(&binary).unwrap();
    let status = common::peer::bounded::wait_within(&mut runner, "the grid's runner");
    let log = std::fs::read_to_string(dir.join("runner.log")).unwrap();
    assert!(status.success(), "{log}");
    let cell = dir.join("out/hopper-random/bc/seed-0");
    assert!(cell.join("result.json").is_file(), "{log}");
    let record: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(cell.join("policy/run.json")).unwrap())
            .unwrap();
    let built = nuno::artifact::sha256_file(Path::new(env!("CARGO_BIN_EXE_nuno-trainer"))).unwrap();
    assert_eq!(record["binary_sha256"].as_str(), Some(built.as_str()));
}

fn two_dataset_grid(dir: &Path, b_file: &str) -> PathBuf {
    generate_hopper(&s(&dir.join("hopper.hdf5")), 300, 0);
    let rows = [
        dataset_row(
            "a",
            "hopper.hdf5",
            "hopper",
            "hopper-random",
            "[\"nuno\", \"mopo\"]",
            "[0, 1]",
        ),
        dataset_row("b", b_file, "hopper", "hopper-medium", "[\"nuno\"]", "[7]"),
    ];
    write_grid(dir, "grid.toml", &rows)
}

/// Seeds outermost across datasets: a sweep cut short has every dataset ×
/// method at its first seed before any at its second.
#[test]
fn cells_run_each_seed_round_over_every_dataset() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let grid = two_dataset_grid(dir, "hopper.hdf5");
    let out = dir.join("out");
    let status = ok(&[
        "experiment",
        "status",
        "--grid",
        &s(&grid),
        "--out",
        &s(&out),
    ]);
    assert_eq!(
        listed(&status),
        [
            "a/nuno/seed-0",
            "a/mopo/seed-0",
            "b/nuno/seed-7",
            "a/nuno/seed-1",
            "a/mopo/seed-1"
        ],
        "{status}"
    );
}

/// The ids of the cells `status` lists.
fn listed(status: &str) -> Vec<&str> {
    status
        .lines()
        .filter_map(|l| l.split_whitespace().nth(1))
        .filter(|id| id.contains('/'))
        .collect()
}

/// `--dataset`, `--method` and `--seed` pick cells (every flag given must
/// match); a value the grid lacks is refused by name before anything runs,
/// and only the picked cells' files need exist.
#[test]
fn flags_pick_some_of_the_cells() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let grid = s(&two_dataset_grid(dir, "missing.hdf5"));
    let out = s(&dir.join("out"));
    let status = |flags: &[&str]| {
        let mut args = vec!["experiment", "status", "--grid", &grid, "--out", &out];
        args.extend_from_slice(flags);
        ok(&args)
    };
    assert_eq!(
        listed(&status(&["--seed", "1"])),
        ["a/nuno/seed-1", "a/mopo/seed-1"]
    );
    assert_eq!(
        listed(&status(&["--method", "mopo", "--dataset", "a"])),
        ["a/mopo/seed-0", "a/mopo/seed-1"]
    );
    assert_eq!(
        listed(&status(&["--seed", "7", "--seed", "0", "--method", "nuno"])),
        ["a/nuno/seed-0", "b/nuno/seed-7"]
    );

    let run = |flags: &[&str]| {
        let mut args = vec!["experiment", "run", "--grid", &grid, "--out", &out];
        args.extend_from_slice(flags);
        fails(&args)
    };
    let error = run(&["--seed", "5"]);
    assert!(
        error.contains("--seed 5: no cell of the grid has it (the grid's: 0, 1, 7)"),
        "{error}"
    );
    let error = run(&["--dataset", "c"]);
    assert!(error.contains("--dataset c: no cell"), "{error}");
    let error = run(&["--method", "tatu-mopo"]);
    assert!(error.contains("--method tatu-mopo: no cell"), "{error}");
    let error = run(&["--method", "dreamer"]);
    assert!(error.contains("unknown method `dreamer`"), "{error}");
    let error = run(&["--dataset", "b", "--seed", "0"]);
    assert!(error.contains("no cell of the grid matches"), "{error}");
    let error = run(&["--dataset", "b"]);
    assert!(
        error.contains("dataset `b`") && error.contains("missing.hdf5 does not exist"),
        "{error}"
    );
    assert!(!dir.join("out").exists(), "nothing ran");
}

#[test]
fn a_local_grid_runs_once_resumes_and_reports() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let grid = hopper_grid(dir, "[\"nuno\"]", "[0, 1]");
    let out = dir.join("out");
    let run = [
        "experiment",
        "run",
        "--grid",
        &grid,
        "--out",
        &s(&out),
        "--jobs",
        "2",
    ];
    let first = ok(&run);
    assert!(first.contains("2 to run"), "{first}");
    let status = ok(&["experiment", "status", "--grid", &grid, "--out", &s(&out)]);
    assert!(status.contains("2/2 cells done"), "{status}");
    // Finished cells are never rerun.
    let again = ok(&run);
    assert!(again.contains("0 to run"), "{again}");
    // Nor do they need their data: a fresh machine makes only the pending cells' files.
    let (data, away) = (dir.join("hopper.hdf5"), dir.join("hopper.away"));
    std::fs::rename(&data, &away).unwrap();
    let without_data = ok(&run);
    assert!(without_data.contains("0 to run"), "{without_data}");
    std::fs::rename(&away, &data).unwrap();
    // A result names its dataset as the grid does, with the file's SHA-256
    // (coreutils' sha256sum, not nuno's hasher).
    let result: serde_json::Value = serde_json::from_slice(
        &std::fs::read(out.join("hopper-random/nuno/seed-0/result.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(result["cell"]["file"], "hopper.hdf5", "{result}");
    let sha256sum = common::peer::bounded::output_within(
        std::process::Command::new("sha256sum").arg(dir.join("hopper.hdf5")),
        "sha256sum",
    );
    let digest = String::from_utf8_lossy(&sha256sum.stdout);
    assert_eq!(
        result["dataset_sha256"].as_str(),
        digest.split_whitespace().next()
    );

    // A cell killed after its second epoch, before its result was written,
    // resumes there: given a longer budget, it trains the third epoch only;
    // so does the finished cell, its result now short of the budget.
    let cell = out.join("hopper-random/nuno/seed-1");
    let before = scores(&cell);
    assert_eq!(before.len(), 2);
    let finished = out.join("hopper-random/nuno/seed-0");
    let finished_before = scores(&finished);
    std::fs::remove_file(cell.join("result.json")).unwrap();
    let row = dataset_row(
        "hopper-random",
        "hopper.hdf5",
        "hopper",
        "hopper-random",
        "[\"nuno\"]",
        "[0, 1]",
    );
    write_grid_with(dir, "grid.toml", 30, &[row]);
    let status = ok(&["experiment", "status", "--grid", &grid, "--out", &s(&out)]);
    assert!(status.contains("0/2 cells done"), "{status}");
    let resumed = ok(&run);
    assert!(resumed.contains("2 to run"), "{resumed}");
    for (cell, before) in [(&cell, &before), (&finished, &finished_before)] {
        let log = std::fs::read_to_string(cell.join("log.txt")).unwrap();
        assert!(log.contains("resumed from"), "{log}");
        let after = scores(cell);
        assert_eq!(after.len(), 3);
        assert_eq!(
            after[..2],
            before[..],
            "{}: kept its first two epochs",
            cell.display()
        );
    }

    let report = ok(&["experiment", "report", "--grid", &grid, "--out", &s(&out)]);
    // The table against the cells' own metrics: best and final per seed, mean ± sample std.
    let per_seed: Vec<(f64, f64)> = [0, 1]
        .iter()
        .map(|seed| {
            let v = scores(&out.join(format!("hopper-random/nuno/seed-{seed}")));
            (
                v.iter().copied().fold(f64::MIN, f64::max),
                *v.last().unwrap(),
            )
        })
        .collect();
    for pick in [|p: &(f64, f64)| p.0, |p: &(f64, f64)| p.1] {
        let (a, b) = (pick(&per_seed[0]), pick(&per_seed[1]));
        let mean = (a + b) / 2.0;
        let std = ((a - mean).powi(2) + (b - mean).powi(2)).sqrt();
        let cell = format!("{mean:.1} ± {std:.1} (2)");
        assert!(report.contains(&cell), "expected {cell} in\n{report}");
    }
    let csv = std::fs::read_to_string(out.join("results.csv")).unwrap();
    assert_eq!(csv.lines().count(), 3, "{csv}");
    // Each cell's policy time is the sum of its epochs' phase times.
    let mut total = 0.0;
    for line in csv.lines().skip(1) {
        let fields: Vec<&str> = line.split(',').collect();
        let cell = out.join(format!("hopper-random/nuno/seed-{}", fields[2]));
        let want: f64 = std::fs::read_to_string(cell.join("policy/metrics.jsonl"))
            .unwrap()
            .lines()
            .map(|l| {
                let v: serde_json::Value = serde_json::from_str(l).unwrap();
                ["updates", "rollouts", "evaluation", "eta_probe"]
                    .iter()
                    .map(|phase| v["seconds"][phase].as_f64().unwrap())
                    .sum::<f64>()
            })
            .sum();
        let got: f64 = fields[7].parse().unwrap();
        assert!((got - want).abs() < 0.06, "{line}: want {want}");
        total += want;
    }
    let hours = format!("{:.2} h of policy training over 2 cells", total / 3600.0);
    assert!(report.contains(&hours), "expected {hours} in\n{report}");
    assert!(out.join("results.md").is_file());
    assert!(out.join("curves-hopper-random.svg").is_file());

    // A grid that gains a method before the finished one (shifting every
    // cell's place), named by another path, keeps its finished cells.
    let row = dataset_row(
        "hopper-random",
        "hopper.hdf5",
        "hopper",
        "hopper-random",
        "[\"nuno-al\", \"nuno\"]",
        "[0, 1]",
    );
    write_grid_with(dir, "grid.toml", 30, &[row]);
    std::fs::create_dir(dir.join("elsewhere")).unwrap();
    let renamed = s(&dir.join("elsewhere/../grid.toml"));
    let status = ok(&[
        "experiment",
        "status",
        "--grid",
        &renamed,
        "--out",
        &s(&out),
    ]);
    assert!(status.contains("2/4 cells done"), "{status}");
    let moved = status.lines().find(|l| l.contains("nuno/seed-1")).unwrap();
    assert!(
        moved.trim_start().starts_with("3 ") && moved.contains("done"),
        "{status}"
    );
    // ... but a budget changed otherwise refuses them,
    let text = std::fs::read_to_string(dir.join("grid.toml")).unwrap();
    std::fs::write(
        dir.join("grid.toml"),
        text.replace("eval_episodes = 1", "eval_episodes = 2"),
    )
    .unwrap();
    let error = fails(&["experiment", "status", "--grid", &grid, "--out", &s(&out)]);
    assert!(
        error.contains("finished under another budget (eval_episodes: 1 then, 2 now)"),
        "{error}"
    );
    // and so does a dataset row pointed at another file.
    let row = dataset_row(
        "hopper-random",
        "grid.toml",
        "hopper",
        "hopper-random",
        "[\"nuno\"]",
        "[0]",
    );
    write_grid_with(dir, "grid.toml", 30, &[row]);
    let error = fails(&["experiment", "status", "--grid", &grid, "--out", &s(&out)]);
    assert!(
        error.contains("written for another cell") && error.contains("hopper.hdf5"),
        "{error}"
    );
}

#[test]
fn methods_in_the_same_kind_of_model_share_one_fit_per_seed() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let grid = hopper_grid(dir, "[\"nuno\", \"nuno-al\"]", "[0]");
    // The grid's model options reach the fit, the row's over the budget's.
    add_to_budget(Path::new(&grid), "model_likelihood = \"data\"");
    add_to_budget(Path::new(&grid), "model_drift_inputs = \"z-scores\"");
    let text = std::fs::read_to_string(&grid).unwrap();
    let row = text.replace("methods = ", "model_drift_inputs = \"pose\"\nmethods = ");
    std::fs::write(&grid, row).unwrap();
    let out = dir.join("out");
    // Both cells start together; one fits the SDE, the other waits for it.
    let run = ok(&[
        "experiment",
        "run",
        "--grid",
        &grid,
        "--out",
        &s(&out),
        "--jobs",
        "2",
    ]);
    assert!(run.contains("2 to run"), "{run}");
    let model = out.join("models/hopper-random/sde/seed-0");
    let metadata: serde_json::Value =
        serde_json::from_slice(&std::fs::read(model.join("model.json")).unwrap()).unwrap();
    assert_eq!(metadata["fit"]["loss"]["likelihood"], "data");
    assert_eq!(metadata["model"]["drift_inputs"], "pose");
    let result = |m: &str| -> serde_json::Value {
        let file = out.join(format!("hopper-random/{m}/seed-0/result.json"));
        serde_json::from_slice(&std::fs::read(file).unwrap()).unwrap()
    };
    assert_eq!(result("nuno")["budget"]["model_drift_inputs"], "pose");
    let fitted = ["nuno", "nuno-al"]
        .iter()
        .filter(|m| {
            let log = out.join(format!("hopper-random/{m}/seed-0/log.txt"));
            std::fs::read_to_string(log)
                .unwrap()
                .contains(&format!("wrote {}", model.display()))
        })
        .count();
    assert_eq!(fitted, 1, "the shared SDE is fitted once");
    // Each cell's policies are its own, trained in the same model.
    let policy = |m: &str| -> serde_json::Value {
        let file = out.join(format!("hopper-random/{m}/seed-0/policy.json"));
        serde_json::from_slice(&std::fs::read(file).unwrap()).unwrap()
    };
    assert_eq!(policy("nuno")["algorithm"], "nuno");
    assert_eq!(policy("nuno-al")["algorithm"], "nuno-al");
    assert_eq!(
        policy("nuno")["dynamics_sha256"],
        policy("nuno-al")["dynamics_sha256"]
    );
    assert!(!model.join("policy.json").exists());
    // A grid edited after its model was fitted: the cell that would train in
    // the old model is refused, naming the model and the setting.
    let text = std::fs::read_to_string(&grid).unwrap();
    let edited = text.replace("\"pose\"", "\"z-scores\"");
    let edited = edited.replace("[budget]\n", "[budget]\nthreshold_max_margin = 1.25\n");
    std::fs::write(&grid, edited).unwrap();
    std::fs::remove_dir_all(out.join("hopper-random/nuno-al")).unwrap();
    let error = fails(&[
        "experiment",
        "run-cell",
        "--cell",
        "1",
        "--grid",
        &grid,
        "--out",
        &s(&out),
    ]);
    assert!(
        error.contains("models/hopper-random/sde/seed-0")
            && error.contains("drift_inputs: \"pose\" then, \"z-scores\" now")
            && error.contains("threshold_max_margin: 1 then, 1.25 now"),
        "{error}"
    );
}

#[test]
#[cfg_attr(
    not(feature = "external-tests"),
    ignore = "needs a single-node Slurm (`make slurm`); `make test` runs it"
)]
fn the_slurm_executor_runs_an_array_job_on_a_real_cluster() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let script = root.join("deploy/slurm/local-cluster.sh");
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let cluster = dir.join("cluster");
    let started = common::peer::bounded::output_within(
        Command::new(&script).arg("start").arg(&cluster),
        "local-cluster.sh start",
    );
    assert!(
        started.status.success(),
        "a single-node Slurm is needed (`make test` installs slurm-wlm and munge; the daemons run as root): {}",
        String::from_utf8_lossy(&started.stderr)
    );
    // Stop exactly what was started, whatever happens below.
    struct Stop<'a>(&'a Path, PathBuf);
    impl Drop for Stop<'_> {
        fn drop(&mut self) {
            let _ = Command::new(self.0).arg("stop").arg(&self.1).status();
        }
    }
    let _stop = Stop(&script, cluster.clone());
    let conf = cluster.join("slurm.conf");

    let grid = hopper_grid(
        dir,
        "[\"nuno\", \"nuno-r\", \"mopo\", \"tatu-mopo\"]",
        "[0]",
    );
    let out = dir.join("out");
    let mut command = Command::new(env!("CARGO_BIN_EXE_nuno-trainer"));
    command
        .args([
            "experiment",
            "run",
            "--grid",
            &grid,
            "--out",
            &s(&out),
            "--executor",
            "slurm",
        ])
        .arg("--slurm-arg=--cpus-per-task=1")
        .env("SLURM_CONF", &conf);
    let submitted =
        common::peer::bounded::output_within(&mut command, "nuno-trainer experiment run");
    let stdout = String::from_utf8_lossy(&submitted.stdout);
    assert!(
        submitted.status.success(),
        "{}",
        String::from_utf8_lossy(&submitted.stderr)
    );
    assert!(stdout.contains("submitted Slurm job"), "{stdout}");
    let script_text = std::fs::read_to_string(out.join("slurm/cells.sh")).unwrap();
    assert!(
        script_text.contains("#SBATCH --array=0,1,2"),
        "{script_text}"
    );

    // Wait for the queue to empty (event polling, bounded only against a hang).
    common::peer::bounded::wait_until("the Slurm array job", || {
        let mut squeue = Command::new("squeue");
        squeue.arg("-h").env("SLURM_CONF", &conf);
        let queue = common::peer::bounded::output_within(&mut squeue, "squeue");
        assert!(
            queue.status.success(),
            "{}",
            String::from_utf8_lossy(&queue.stderr)
        );
        queue.stdout.is_empty()
    });
    let status = ok(&["experiment", "status", "--grid", &grid, "--out", &s(&out)]);
    assert!(
        status.contains("4/4 cells done"),
        "{status}\n{}",
        logs(&out.join("slurm"))
    );
    let report = ok(&["experiment", "report", "--grid", &grid, "--out", &s(&out)]);
    assert!(
        report.contains("| dataset | nuno | nuno-r | mopo | tatu-mopo |"),
        "{report}"
    );
    // One seed per method: a score without a spread.
    assert!(
        report.contains(" (1) |") && !report.contains("± 0.0 (1)"),
        "{report}"
    );
    assert!(
        out.join("models/hopper-random/ensemble/seed-0/ensemble.json")
            .is_file()
    );
}

fn logs(dir: &Path) -> String {
    std::fs::read_dir(dir)
        .map(|entries| {
            entries
                .filter_map(|e| std::fs::read_to_string(e.ok()?.path()).ok())
                .collect::<Vec<_>>()
                .join("\n")
        })
        .unwrap_or_default()
}

#[test]
fn a_grid_runs_a_system_file_and_scores_it_in_the_model() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let example = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/pendulum");
    common::copy_dir(&example, &dir.join("pendulum"));
    let row = "\n[[datasets]]\nname = \"pendulum\"\nfile = \"pendulum/log.csv\"\n\
               system = \"pendulum/system.toml\"\n\
               policy = { horizon = 5, cvar_alpha = 0.95, penalty = 1.0 }\n\
               methods = [\"nuno\", \"mopo\"]\nseeds = [0]\n";
    let grid = s(&write_grid(dir, "grid.toml", &[row.to_string()]));
    let out = dir.join("out");
    let first = ok(&["experiment", "run", "--grid", &grid, "--out", &s(&out)]);
    assert!(first.contains("2 to run"), "{first}");
    for method in ["nuno", "mopo"] {
        let result: serde_json::Value = serde_json::from_slice(
            &std::fs::read(out.join(format!("pendulum/{method}/seed-0/result.json"))).unwrap(),
        )
        .unwrap();
        assert_eq!(result["cell"]["system"], "pendulum/system.toml", "{result}");
        assert_eq!(result["cell"]["policy"]["horizon"], 5, "{result}");
        // Without a simulator the score is the return in the model: the
        // pendulum's rewards are ≤ 0 at every step, so the return is too.
        let best = result["best_score"].as_f64().unwrap();
        assert!(best <= 0.0 && best.is_finite(), "{result}");
        let metrics = out.join(format!("pendulum/{method}/seed-0/policy/metrics.jsonl"));
        let metrics = std::fs::read_to_string(metrics).unwrap();
        assert!(
            metrics.lines().all(|l| l.contains("\"in_model\":true")),
            "{metrics}"
        );
    }
    // A row is a task with a preset or policy settings, or a system with
    // policy settings, not a mix.
    let mixed = row.replace("system = ", "task = \"hopper\"\nsystem = ");
    let bad = s(&write_grid(dir, "mixed.toml", &[mixed]));
    let error = fails(&["experiment", "run", "--grid", &bad, "--out", &s(&out)]);
    assert!(
        error.contains("needs task and preset") && error.contains("pendulum"),
        "{error}"
    );
}
