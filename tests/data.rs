//! Datasets: the D4RL writer read back by Rust and by h5py, real-world file
//! quirks and bad files made with h5py/numpy, NeoRL and Minari readers,
//! generation, normalisation, samplers and splits.

mod common;

use std::path::{Path, PathBuf};

use ndarray::{Array1, Array2};
use nuno::agent::PortableActor;
use nuno::data::{
    DataError, Dataset, DatasetFormat, DatasetParts, GenerateConfig, Normalizer, NormalizerConfig,
    StartStateSampler, TransitionSampler, WindowSampler, generate, read_d4rl, read_dataset,
    read_minari, read_neorl, write_d4rl,
};
use nuno::envs::{MujocoTask, System, TaskConfig, TaskName};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::Deserialize;

fn small_hopper_dataset(transitions: usize, seed: u64) -> Dataset {
    let task = TaskConfig::d4rl(TaskName::Hopper);
    let policy = PortableActor::rlkit_random(11, 3, &[32, 32], seed);
    let config = GenerateConfig::new(task, "random", transitions, seed);
    generate(&config, &policy, &policy.rlkit_description(), &|_| {}).unwrap()
}

/// The D4RL/NeoRL/Minari fixtures of tests/python/datasets.py, written once per test.
fn fixtures() -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().to_path_buf();
    common::run_python(
        "datasets.py",
        &["write-fixtures".as_ref(), path.as_os_str()],
        &path,
    );
    (dir, path)
}

#[test]
fn generated_random_dataset_follows_d4rl_recipe() {
    let dataset = small_hopper_dataset(3000, 1);
    assert_eq!(dataset.len(), 3000);
    assert_eq!((dataset.obs_dim(), dataset.act_dim()), (11, 3));
    assert_eq!(dataset.metadata["kind"], "random");
    assert_eq!(dataset.metadata["task"], "hopper");
    assert!(dataset.metadata["policy"].contains("tanh-Gaussian"));
    // Every trajectory ends with a fall or a cut; the last was cut to fit 3000.
    for t in dataset.trajectories() {
        let last = t.end - 1;
        assert!(dataset.terminals[last] ^ dataset.timeouts[last]);
        assert!((t.start..last).all(|i| !dataset.terminals[i] && !dataset.timeouts[i]));
    }
    let last = dataset.len() - 1;
    assert!(dataset.timeouts[last] || dataset.terminals[last]);
    // Random hopper episodes fall within tens of steps, as in D4RL's hopper-random.
    let mean_length = 3000.0 / dataset.trajectories().len() as f64;
    assert!(
        (10.0..60.0).contains(&mean_length),
        "mean length {mean_length}"
    );
    // Sampled tanh-Gaussian actions: inside (-1, 1) and spread out.
    assert!(dataset.actions.iter().all(|a| a.abs() < 1.0));
    let spread = dataset.actions.iter().map(|a| a * a).sum::<f32>() / dataset.actions.len() as f32;
    assert!(
        spread > 0.2,
        "actions too concentrated: mean square {spread}"
    );
    // infos/qpos and infos/qvel are the MuJoCo state at each observation.
    let (qpos, qvel) = (
        dataset.qpos.as_ref().unwrap(),
        dataset.qvel.as_ref().unwrap(),
    );
    for i in [0, 100, 2999] {
        assert_eq!(dataset.observations[[i, 0]], qpos[[i, 1]]);
        assert_eq!(
            dataset.observations[[i, 5]],
            qvel[[i, 0]].clamp(-10.0, 10.0)
        );
    }
}

#[test]
fn generation_depends_on_the_seed_only() {
    let run = |threads: usize, seed: u64| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| small_hopper_dataset(1500, seed))
    };
    let a = run(1, 4);
    assert_eq!(a, run(2, 4));
    assert_ne!(a.observations, run(2, 5).observations);
}

#[derive(Deserialize)]
struct H5pyReport {
    keys: Vec<String>,
    infos: Vec<String>,
    metadata: std::collections::BTreeMap<String, String>,
    dtypes: std::collections::BTreeMap<String, String>,
    shapes: std::collections::BTreeMap<String, Vec<usize>>,
    compression: Option<String>,
    continuity_max_error: f64,
    qpos_max_error: f64,
    qvel_max_error: f64,
    return_sum: f64,
}

#[test]
#[cfg_attr(
    not(feature = "external-tests"),
    ignore = "needs the Python venv (`make venv`); `make test` runs it"
)]
fn written_files_round_trip_and_h5py_reads_d4rl_layout() {
    let dataset = small_hopper_dataset(2000, 2);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("nested/hopper-random.hdf5");
    write_d4rl(&dataset, &path).unwrap();
    // Nothing but the file itself is left behind by the atomic write.
    let names: Vec<_> = std::fs::read_dir(path.parent().unwrap())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names, vec![std::ffi::OsString::from("hopper-random.hdf5")]);

    let back = read_d4rl(&path).unwrap();
    assert_eq!(back.observations, dataset.observations);
    assert_eq!(back.actions, dataset.actions);
    assert_eq!(back.rewards, dataset.rewards);
    assert_eq!(back.next_observations, dataset.next_observations);
    assert_eq!(back.terminals, dataset.terminals);
    assert_eq!(back.timeouts, dataset.timeouts);
    assert_eq!(back.qpos, dataset.qpos);
    assert_eq!(back.qvel, dataset.qvel);
    assert_eq!(back.action_log_probs, dataset.action_log_probs);
    assert_eq!(back.trajectories(), dataset.trajectories());
    assert_eq!(back.metadata["seed"], "2");
    assert_eq!(
        read_dataset(&path, None).unwrap().observations,
        dataset.observations
    );

    let report_path = dir.path().join("report.json");
    common::run_python(
        "datasets.py",
        &[
            "inspect-d4rl".as_ref(),
            path.as_os_str(),
            report_path.as_os_str(),
        ],
        dir.path(),
    );
    let report: H5pyReport = serde_json::from_slice(&std::fs::read(&report_path).unwrap()).unwrap();
    for key in [
        "actions",
        "infos",
        "metadata",
        "next_observations",
        "observations",
        "rewards",
        "terminals",
        "timeouts",
    ] {
        assert!(
            report.keys.contains(&key.to_string()),
            "h5py misses `{key}`"
        );
    }
    assert_eq!(report.infos, vec!["action_log_probs", "qpos", "qvel"]);
    assert_eq!(report.dtypes["observations"], "float32");
    assert_eq!(report.dtypes["rewards"], "float32");
    assert_eq!(report.dtypes["terminals"], "bool");
    assert_eq!(report.dtypes["timeouts"], "bool");
    assert_eq!(report.shapes["observations"], vec![2000, 11]);
    assert_eq!(report.shapes["rewards"], vec![2000]);
    assert_eq!(report.shapes["infos/qpos"], vec![2000, 6]);
    assert_eq!(report.shapes["infos/qvel"], vec![2000, 6]);
    assert_eq!(report.shapes["infos/action_log_probs"], vec![2000]);
    assert_eq!(report.compression.as_deref(), Some("gzip"));
    assert_eq!(report.metadata["task"], "hopper");
    assert_eq!(report.metadata["kind"], "random");
    assert_eq!(report.continuity_max_error, 0.0);
    assert_eq!(report.qpos_max_error, 0.0);
    assert_eq!(report.qvel_max_error, 0.0);
    let ours: f64 = dataset.rewards.iter().map(|&r| f64::from(r)).sum();
    assert!((report.return_sum - ours).abs() < 1e-6 * ours.abs().max(1.0));
}

#[test]
#[cfg_attr(
    not(feature = "external-tests"),
    ignore = "needs the Python venv (`make venv`); `make test` runs it"
)]
fn d4rl_quirks_are_repaired_not_copied() {
    let (_dir, d) = fixtures();
    // Boundary missing from the flags, float64 observations, rewards [n, 1].
    let quirky = read_d4rl(&d.join("quirky.hdf5")).unwrap();
    assert_eq!(
        quirky.len(),
        16,
        "no transition dropped when next_observations exist"
    );
    let lengths: Vec<usize> = quirky.trajectories().iter().map(|t| t.len()).collect();
    assert_eq!(lengths, vec![5, 7, 4]);
    assert!(quirky.terminals[4] && quirky.timeouts[11] && quirky.timeouts[15]);
    assert!(
        !quirky.terminals[11],
        "the recovered boundary is a cut, not a fall"
    );

    // No next_observations: successors fill in, unknown next states are dropped.
    let no_next = read_d4rl(&d.join("no_next.hdf5")).unwrap();
    assert_eq!(no_next.len(), 13);
    assert_eq!(no_next.metadata["dropped_without_next_observation"], "3");
    let lengths: Vec<usize> = no_next.trajectories().iter().map(|t| t.len()).collect();
    assert_eq!(lengths, vec![4, 6, 3]);
    for t in no_next.trajectories() {
        for i in t.start..t.end - 1 {
            assert_eq!(
                no_next.next_observations.row(i),
                no_next.observations.row(i + 1)
            );
        }
    }
    assert_eq!(no_next.next_observations.row(3), quirky.observations.row(4));

    // Files without `timeouts` still split, on terminals and on continuity.
    let no_timeouts = read_d4rl(&d.join("no_timeouts.hdf5")).unwrap();
    assert_eq!(no_timeouts.trajectories().len(), 3);
}

fn expect_error(path: &Path, check: impl Fn(&DataError) -> bool) -> String {
    let err = read_dataset(path, None).unwrap_err();
    assert!(
        check(&err),
        "unexpected error for {}: {err:?}",
        path.display()
    );
    let message = err.to_string();
    let name = path.file_name().unwrap().to_string_lossy().to_string();
    assert!(
        message.contains(&name),
        "`{message}` does not name the file"
    );
    message
}

#[test]
#[cfg_attr(
    not(feature = "external-tests"),
    ignore = "needs the Python venv (`make venv`); `make test` runs it"
)]
fn bad_files_are_refused_with_what_is_wrong() {
    let (_dir, d) = fixtures();
    let m = expect_error(
        &d.join("missing_actions.hdf5"),
        |e| matches!(e, DataError::MissingKey { key, .. } if key == "actions"),
    );
    assert!(m.contains("missing key `actions`"));
    let m = expect_error(
        &d.join("short_rewards.hdf5"),
        |e| matches!(e, DataError::LengthMismatch { key, expected: 16, got: 15, .. } if key == "rewards"),
    );
    assert!(m.contains("`rewards` has 15 rows, expected 16"));
    expect_error(
        &d.join("nan_obs.hdf5"),
        |e| matches!(e, DataError::NonFinite { key, row: 6, .. } if key == "observations"),
    );
    expect_error(&d.join("empty.hdf5"), |e| {
        matches!(e, DataError::Empty { .. })
    });
    expect_error(
        &d.join("flat_obs.hdf5"),
        |e| matches!(e, DataError::BadShape { key, .. } if key == "observations"),
    );
    expect_error(&d.join("garbage.hdf5"), |e| {
        matches!(e, DataError::Hdf5 { .. })
    });
    expect_error(&d.join("absent.hdf5"), |e| {
        matches!(e, DataError::Io { .. })
    });
    expect_error(
        &d.join("neorl_missing.npz"),
        |e| matches!(e, DataError::MissingKey { key, .. } if key == "next_obs"),
    );

    // Widths are checked against the task the user names.
    let wide = d.join("wide_obs.hdf5");
    let dataset = read_d4rl(&wide).unwrap();
    let err = dataset
        .check_system(&System::Task(TaskConfig::d4rl(TaskName::Hopper)), &wide)
        .unwrap_err();
    assert!(matches!(
        err,
        DataError::WrongDimension {
            expected: 11,
            got: 17,
            ..
        }
    ));
    assert!(
        err.to_string()
            .contains("wide_obs.hdf5: `observations` rows are 17 wide, but hopper")
    );
}

#[test]
#[cfg_attr(
    not(feature = "external-tests"),
    ignore = "needs the Python venv (`make venv`); `make test` runs it"
)]
fn neorl_and_minari_files_are_read() {
    let (_dir, d) = fixtures();
    let neorl = read_neorl(&d.join("neorl.npz")).unwrap();
    assert_eq!((neorl.len(), neorl.obs_dim(), neorl.act_dim()), (16, 12, 3));
    let lengths: Vec<usize> = neorl.trajectories().iter().map(|t| t.len()).collect();
    assert_eq!(lengths, vec![5, 7, 4]);
    assert!(neorl.terminals[4] && !neorl.timeouts[4]);
    assert!(neorl.timeouts[11] && neorl.timeouts[15]);
    neorl
        .check_system(
            &System::Task(TaskConfig::neorl(TaskName::Hopper)),
            &d.join("neorl.npz"),
        )
        .unwrap();
    assert_eq!(
        DatasetFormat::detect(&d.join("neorl.npz")),
        DatasetFormat::Neorl
    );

    let minari_dir = d.join("minari");
    assert_eq!(DatasetFormat::detect(&minari_dir), DatasetFormat::Minari);
    let minari = read_minari(&minari_dir).unwrap();
    assert_eq!(minari.len(), 16);
    let lengths: Vec<usize> = minari.trajectories().iter().map(|t| t.len()).collect();
    assert_eq!(lengths, vec![5, 7, 4]);
    assert!(minari.terminals[4]);
    assert!(
        minari.timeouts[11] && minari.timeouts[15],
        "unflagged episode end becomes a cut"
    );
    assert_eq!(minari.rewards[6], 1.0);
    assert_eq!(
        read_dataset(&minari_dir.join("data/main_data.hdf5"), None).unwrap(),
        minari
    );
}

/// A hand-made dataset: trajectories of the given lengths, states counting up.
fn counting_dataset(lengths: &[usize]) -> Dataset {
    let n: usize = lengths.iter().sum();
    let mut observations = Array2::zeros((n, 2));
    let mut next_observations = Array2::zeros((n, 2));
    let mut timeouts = vec![false; n];
    let mut i = 0;
    for (t, &len) in lengths.iter().enumerate() {
        for k in 0..len {
            let base = (100 * t + k) as f32;
            observations
                .row_mut(i)
                .assign(&ndarray::arr1(&[base, -base]));
            next_observations
                .row_mut(i)
                .assign(&ndarray::arr1(&[base + 1.0, -base - 1.0]));
            i += 1;
        }
        timeouts[i - 1] = true;
    }
    let parts = DatasetParts {
        actions: Array2::from_shape_fn((n, 1), |(i, _)| i as f32),
        rewards: Array1::from_shape_fn(n, |i| i as f32),
        observations,
        next_observations,
        terminals: vec![false; n],
        timeouts,
        qpos: None,
        qvel: None,
        action_log_probs: None,
        metadata: Default::default(),
    };
    Dataset::from_parts(parts, Path::new("counting")).unwrap()
}

#[test]
fn windows_never_cross_trajectories() {
    let dataset = counting_dataset(&[3, 1, 5]);
    let sampler = WindowSampler::new(&dataset, 2).unwrap();
    // Windows of 2 transitions: 2 in the first trajectory, 0 in the second, 4 in the third.
    assert_eq!(sampler.starts(), &[0, 1, 4, 5, 6, 7]);
    let batch = sampler.sample(500, &mut ChaCha8Rng::seed_from_u64(0));
    assert_eq!((batch.batch, batch.horizon), (500, 2));
    assert_eq!(batch.states.len(), 500 * 3 * 2);
    for w in 0..500 {
        let states = &batch.states[w * 6..(w + 1) * 6];
        // Each step moves the counter by one: the window stayed in its trajectory.
        assert_eq!(states[2], states[0] + 1.0);
        assert_eq!(states[4], states[0] + 2.0);
        assert_eq!(batch.actions[w * 2 + 1], batch.actions[w * 2] + 1.0);
    }
    let gathered = sampler.gather(&[4]);
    assert_eq!(
        gathered.states,
        vec![200.0, -200.0, 201.0, -201.0, 202.0, -202.0]
    );
    assert_eq!(gathered.rewards, vec![4.0, 5.0]);

    let pieces = WindowSampler::non_overlapping(&dataset, 2).unwrap();
    assert_eq!(pieces.starts(), &[0, 4, 6]);
    let err = WindowSampler::new(&dataset, 6).unwrap_err();
    assert!(matches!(err, DataError::NoWindows { horizon: 6 }));
}

#[test]
fn transition_and_start_samplers_draw_dataset_rows() {
    let dataset = counting_dataset(&[4, 4]);
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let batch = TransitionSampler::new(&dataset).sample(64, &mut rng);
    for k in 0..64 {
        let i = batch.actions[k] as usize;
        assert_eq!(batch.rewards[k], i as f32);
        assert_eq!(batch.observations[2 * k], dataset.observations[[i, 0]]);
        assert_eq!(
            batch.next_observations[2 * k],
            dataset.observations[[i, 0]] + 1.0
        );
    }
    let starts = StartStateSampler::new(&dataset).sample(32, &mut rng);
    assert_eq!(starts.len(), 64);
    assert!(starts.chunks(2).all(|s| s[1] == -s[0]));
    let distinct: std::collections::BTreeSet<i64> = starts.iter().map(|&v| v as i64).collect();
    assert!(distinct.len() > 4, "start states should vary");
}

#[test]
fn normaliser_matches_hand_computed_statistics() {
    let dataset = counting_dataset(&[4]);
    let normalizer = Normalizer::fit(&dataset, &NormalizerConfig::default());
    // observations[:, 0] = 0, 1, 2, 3: mean 1.5, population std sqrt(1.25).
    assert_eq!(normalizer.state.mean, vec![1.5, -1.5]);
    assert!((normalizer.state.std[0] - 1.25f32.sqrt()).abs() < 1e-6);
    assert_eq!(normalizer.reward.mean, vec![1.5]);
    let mut row = vec![3.0, -3.0];
    normalizer.state.normalize(&mut row);
    assert!((row[0] - 1.5 / 1.25f32.sqrt()).abs() < 1e-6);
    normalizer.state.denormalize(&mut row);
    assert!((row[0] - 3.0).abs() < 1e-6 && (row[1] + 3.0).abs() < 1e-6);

    // A constant dimension gets the floor, not a division by zero.
    let constant = counting_dataset(&[1]);
    let floored = Normalizer::fit(&constant, &NormalizerConfig { std_floor: 0.5 });
    assert_eq!(floored.state.std, vec![0.5, 0.5]);
}

#[test]
fn split_by_trajectory_keeps_trajectories_whole() {
    let dataset = counting_dataset(&[3, 4, 5, 6, 7, 8, 9, 10, 11, 12]);
    let (train, valid) = dataset.split_by_trajectory(0.2, 3);
    assert_eq!(valid.trajectories().len(), 2);
    assert_eq!(train.trajectories().len(), 8);
    assert_eq!(train.len() + valid.len(), dataset.len());
    for part in [&train, &valid] {
        for t in part.trajectories() {
            // A whole original trajectory: its first state is a multiple of 100.
            assert_eq!(part.observations[[t.start, 0]] % 100.0, 0.0);
            assert!(part.timeouts[t.end - 1]);
        }
    }
    assert_eq!(dataset.split_by_trajectory(0.2, 3).1, valid);
    assert_ne!(
        dataset.split_by_trajectory(0.2, 4).1.observations,
        valid.observations
    );
}

#[test]
fn a_task_probe_matches_generated_widths() {
    let task = MujocoTask::new(&TaskConfig::neorl(TaskName::Walker2d)).unwrap();
    let policy = PortableActor::rlkit_random(task.obs_dim(), task.act_dim(), &[16], 0);
    let config = GenerateConfig::new(task.config().clone(), "random", 50, 0);
    let dataset = generate(&config, &policy, "test", &|_| {}).unwrap();
    assert_eq!(dataset.obs_dim(), 18);
    dataset
        .check_system(&System::Task(task.config().clone()), Path::new("generated"))
        .unwrap();
}
