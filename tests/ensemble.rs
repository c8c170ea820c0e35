//! The Gaussian ensemble learns a known linear-Gaussian system: its means the
//! true conditional mean, its variances the injected noise, per output; the
//! fit stops by MOPO's rule and ranks the elites by holdout error.

use burn::tensor::{Device, Tensor, TensorData};
use ndarray::{Array1, Array2};
use nuno::data::{Dataset, DatasetMetadata, DatasetParts};
use nuno::ensemble::{
    AdversarialConfig, AdversarialEnsemble, EnsembleConfig, EnsembleDynamics, EnsembleFit,
    EnsembleUncertainty, GaussianEnsemble, fit_ensemble,
};
use nuno::infer::Kernel;
use nuno::nn::to_f32_vec;
use nuno::shared::BatchDynamics;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

/// Noise std of (Δs₀, Δs₁, r).
const NOISE: [f32; 3] = [0.02, 0.1, 0.05];

/// E[(Δs, r) | s, a] of the system.
fn true_mean(s: &[f32], a: f32) -> [f32; 3] {
    [0.3 * a + 0.1 * s[0], -0.2 * s[1], s[0] - 0.5 * a]
}

fn linear_gaussian(n: usize, seed: u64) -> Dataset {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (mut obs, mut act, mut next, mut rew) = (vec![], vec![], vec![], vec![]);
    for _ in 0..n {
        let s: Vec<f32> = (0..2).map(|_| rng.random_range(-1.0..1.0)).collect();
        let a: f32 = rng.random_range(-1.0..1.0);
        let m = true_mean(&s, a);
        let e: Vec<f32> = (0..3)
            .map(|d| NOISE[d] * rng.sample::<f32, _>(StandardNormal))
            .collect();
        obs.extend(&s);
        act.push(a);
        next.extend([s[0] + m[0] + e[0], s[1] + m[1] + e[1]]);
        rew.push(m[2] + e[2]);
    }
    let parts = DatasetParts {
        observations: Array2::from_shape_vec((n, 2), obs).unwrap(),
        actions: Array2::from_shape_vec((n, 1), act).unwrap(),
        rewards: Array1::from(rew),
        next_observations: Array2::from_shape_vec((n, 2), next).unwrap(),
        terminals: vec![false; n],
        timeouts: vec![true; n],
        qpos: None,
        qvel: None,
        action_log_probs: None,
        metadata: DatasetMetadata::new(),
    };
    Dataset::from_parts(parts, std::path::Path::new("<linear-gaussian>")).unwrap()
}

fn small_config() -> EnsembleConfig {
    EnsembleConfig::new()
        .with_members(4)
        .with_elites(2)
        .with_hidden(vec![32, 32])
        .with_weight_decay(vec![2.5e-5, 5e-5, 1e-4])
        .with_batch_size(32)
        .with_max_epochs(Some(150))
}

/// The bounds, then every member's weights and biases.
fn params(model: &GaussianEnsemble) -> Vec<f32> {
    let mut all = to_f32_vec(model.max_logvar.val());
    all.extend(to_f32_vec(model.min_logvar.val()));
    for member in &model.members {
        for layer in &member.layers {
            all.extend(to_f32_vec(layer.weight.val()));
            all.extend(to_f32_vec(layer.bias.as_ref().unwrap().val()));
        }
    }
    all
}

fn largest_difference(a: &[f32], b: &[f32]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

fn fitted() -> EnsembleFit {
    fit_ensemble(
        &linear_gaussian(4000, 0),
        &small_config(),
        Kernel::Fused,
        &Device::flex(),
        None,
        &mut |_| Ok(()),
    )
    .unwrap()
}

/// The fused trainer against burn's autodiff: from the same initial weights,
/// on the same batches, with the same Adam, every epoch's training loss and
/// holdout errors and the final weights agree to float rounding.
#[test]
fn the_fused_fit_follows_burns_autodiff() {
    let data = linear_gaussian(1200, 3);
    let config = small_config()
        .with_members(3)
        .with_hidden(vec![24, 24])
        // A lower bound the smallest noise (log 0.02² ≈ −7.8) presses on, so
        // that the data's gradient reaches it.
        .with_min_logvar_init(-6.0)
        .with_max_epochs(Some(3));
    let fit = |kernel| {
        fit_ensemble(&data, &config, kernel, &Device::flex(), None, &mut |_| {
            Ok(())
        })
        .unwrap()
    };
    let (burn, fused) = (fit(Kernel::Burn), fit(Kernel::Fused));
    let close = |a: f64, b: f64, what: &str| {
        assert!(
            (a - b).abs() <= 1e-4 * a.abs().max(b.abs()) + 1e-6,
            "{what}: burn {a}, fused {b}"
        );
    };
    assert_eq!(burn.history.len(), 3);
    assert_eq!(fused.history.len(), 3);
    for (b, f) in burn.history.iter().zip(&fused.history) {
        close(
            b.train_loss,
            f.train_loss,
            &format!("epoch {} loss", b.epoch),
        );
        for (m, (bm, fm)) in b.holdout_mse.iter().zip(&f.holdout_mse).enumerate() {
            close(
                f64::from(*bm),
                f64::from(*fm),
                &format!("epoch {} member {m}", b.epoch),
            );
        }
    }
    // 90 Adam steps in: every parameter within 1e-4 of burn's (weights are O(0.1);
    // a wrong bound gradient moves them by 1e-2).
    let (b, f) = (params(&burn.model), params(&fused.model));
    let worst = largest_difference(&b, &f);
    assert!(worst < 1e-4, "largest parameter difference {worst}");
    // The bounds moved from their initial 0.5 / −10: their gradients are in.
    assert!(b[..3].iter().all(|&v| v != 0.5), "{:?}", &b[..3]);
    assert_eq!(burn.elites, fused.elites);
}

/// A fit stopped after its second epoch, checkpointed to disk and resumed,
/// ends where the uninterrupted fit ends: bit for bit on the same trainer,
/// within rounding when the other trainer resumes it.
#[test]
fn a_checkpointed_fit_resumes_where_it_stopped() {
    use nuno::artifact::{EnsembleFitShape, load_ensemble_checkpoint, save_ensemble_checkpoint};
    use nuno::ensemble::EnsembleError;

    let data = linear_gaussian(900, 5);
    let config = small_config().with_members(3).with_hidden(vec![16, 16]);
    let shape = EnsembleFitShape {
        rows: data.len(),
        obs_dim: 2,
        act_dim: 1,
    };
    let device = Device::flex();
    let whole = fit_ensemble(
        &data,
        &config.clone().with_max_epochs(Some(4)),
        Kernel::Fused,
        &device,
        None,
        &mut |_| Ok(()),
    )
    .unwrap();
    assert_eq!(whole.history.len(), 4);

    for (first, second) in [
        (Kernel::Fused, Kernel::Fused),
        (Kernel::Burn, Kernel::Fused),
        (Kernel::Fused, Kernel::Burn),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let stopped = fit_ensemble(&data, &config, first, &device, None, &mut |state| {
            save_ensemble_checkpoint(dir.path(), &config, &shape, state).unwrap();
            if state.history.len() == 2 {
                return Err(EnsembleError::Checkpoint("stopped".into()));
            }
            Ok(())
        });
        assert!(stopped.unwrap_err().to_string().contains("stopped"));
        let latest = nuno::artifact::latest_checkpoint(dir.path())
            .unwrap()
            .unwrap();
        assert!(latest.ends_with("epoch-000002"), "{}", latest.display());
        // The epoch cap may change on resume; the rest of the config may not.
        let capped = config.clone().with_max_epochs(Some(4));
        let state = load_ensemble_checkpoint(&latest, &capped, &shape, &device).unwrap();
        let resumed = fit_ensemble(
            &data,
            &capped,
            second,
            &device,
            Some(state),
            &mut |_| Ok(()),
        )
        .unwrap();
        assert_eq!(resumed.history.len(), 4);
        let weights = |fit: &EnsembleFit| {
            let mut all = to_f32_vec(fit.model.max_logvar.val());
            for member in &fit.model.members {
                for layer in &member.layers {
                    all.extend(to_f32_vec(layer.weight.val()));
                }
            }
            all
        };
        if first == second {
            assert_eq!(resumed.history, whole.history);
            assert_eq!(weights(&resumed), weights(&whole));
        } else {
            for (a, b) in resumed.history.iter().zip(&whole.history) {
                let rel = (a.train_loss - b.train_loss).abs() / b.train_loss.abs();
                assert!(
                    rel < 1e-4,
                    "epoch {}: {} vs {}",
                    a.epoch,
                    a.train_loss,
                    b.train_loss
                );
            }
            let worst = weights(&resumed)
                .iter()
                .zip(&weights(&whole))
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f32::max);
            assert!(worst < 1e-4, "{worst}");
        }

        // Another config's or dataset's checkpoint is refused by name.
        let other = config.clone().with_hidden(vec![8, 8]);
        let error = load_ensemble_checkpoint(&latest, &other, &shape, &device).unwrap_err();
        assert!(
            error.to_string().contains("other settings or data"),
            "{error}"
        );
        let more_rows = EnsembleFitShape {
            rows: 901,
            ..shape.clone()
        };
        assert!(load_ensemble_checkpoint(&latest, &config, &more_rows, &device).is_err());
    }
}

#[test]
fn the_ensemble_learns_a_linear_gaussian_system() {
    let device = Device::flex();
    let data = linear_gaussian(4000, 0);
    let config = small_config();
    let mut epochs = 0;
    let fit = fit_ensemble(&data, &config, Kernel::Fused, &device, None, &mut |_| {
        epochs += 1;
        Ok(())
    })
    .unwrap();
    assert_eq!(epochs, fit.history.len());

    // MOPO's stopping rule, replayed from the history: the fit ends after 5
    // epochs in which no member beat its best holdout MSE by more than 1 %.
    let mut best = vec![f32::INFINITY; 4];
    let mut since = 0;
    for (i, epoch) in fit.history.iter().enumerate() {
        let improved = epoch
            .holdout_mse
            .iter()
            .zip(&mut best)
            .fold(false, |any, (&mse, b)| {
                let better = b.is_infinite() || (*b - mse) / *b > 0.01;
                if better {
                    *b = mse;
                }
                any || better
            });
        assert_eq!(improved, epoch.improved, "epoch {}", i + 1);
        since = if improved { 0 } else { since + 1 };
        assert!(
            since < 5 || i + 1 == fit.history.len(),
            "ran past the stop at epoch {}",
            i + 1
        );
    }
    assert!(since == 5 || fit.history.len() == 150);
    assert_eq!(fit.holdout_mse, best);
    // The elites are the two members with the lowest best holdout MSE.
    let mut ranked: Vec<usize> = (0..4).collect();
    ranked.sort_by(|&a, &b| best[a].total_cmp(&best[b]));
    assert_eq!(fit.elites, ranked[..2]);

    // Against the system itself, on fresh points: each elite's mean is within a
    // fraction of the noise of the true mean, its std within 30 % of the noise
    // (a short fit, and training order varies with the cores' scheduling).
    let test = linear_gaussian(2000, 1);
    let n = test.len();
    let mut x = Vec::new();
    for i in 0..n {
        for (j, v) in test
            .observations
            .row(i)
            .iter()
            .chain(test.actions.row(i).iter())
            .enumerate()
        {
            x.push((v - fit.scaler.mean[j]) / fit.scaler.std[j]);
        }
    }
    let x = Tensor::<2>::from_data(TensorData::new(x, [n, 3]), &device);
    for &m in &fit.elites {
        let (mean, logvar) = fit.model.member(m, x.clone());
        let (mean, logvar) = (to_f32_vec(mean), to_f32_vec(logvar));
        for d in 0..3 {
            let mut squared_error = 0.0f64;
            let mut std = 0.0f64;
            for i in 0..n {
                let s = [test.observations[[i, 0]], test.observations[[i, 1]]];
                let truth = true_mean(&s, test.actions[[i, 0]])[d];
                squared_error += f64::from(mean[i * 3 + d] - truth).powi(2);
                std += f64::from((0.5 * logvar[i * 3 + d]).exp());
            }
            let rmse = (squared_error / n as f64).sqrt();
            let std = std / n as f64;
            let noise = f64::from(NOISE[d]);
            assert!(
                rmse < 0.35 * noise,
                "member {m} output {d}: mean error {rmse:.4} vs noise {noise}"
            );
            assert!(
                (std / noise - 1.0).abs() < 0.3,
                "member {m} output {d}: std {std:.4} vs noise {noise}"
            );
        }
    }
}

#[test]
fn bad_ensemble_settings_are_refused_by_name() {
    let device = Device::flex();
    let data = linear_gaussian(100, 0);
    let cases = [
        (EnsembleConfig::new().with_elites(8), "elites"),
        (
            EnsembleConfig::new().with_weight_decay(vec![1e-4]),
            "weight_decay",
        ),
        (
            EnsembleConfig::new().with_holdout_fraction(1.0),
            "holdout_fraction",
        ),
    ];
    for (config, name) in cases {
        let error = fit_ensemble(
            &data,
            &config,
            Kernel::Fused,
            &device,
            None,
            &mut |_| Ok(()),
        )
        .unwrap_err()
        .to_string();
        assert!(error.contains(name), "{error}");
    }
}

#[test]
fn stepped_as_dynamics_it_samples_the_system_and_reports_its_spread() {
    let fit = fitted();
    let dynamics = EnsembleDynamics::new(&fit, 2, 1, EnsembleUncertainty::MaxAleatoric);
    assert_eq!((dynamics.state_dim(), dynamics.noise_dim()), (3, 4));
    // One (s, a), many samples: state = (s, r_c = 0).
    let (s, a) = ([0.4f32, -0.3], 0.5f32);
    let rows = 20_000;
    let states: Vec<f32> = (0..rows).flat_map(|_| [s[0], s[1], 0.0]).collect();
    let actions = vec![a; rows];
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let noise: Vec<f32> = (0..rows * 4).map(|_| rng.sample(StandardNormal)).collect();
    let step = dynamics.step(&states, &actions, &noise);

    // Each of the two elites serves about half the rows.
    let first_mean = &step.means[..3];
    let share = (0..rows)
        .filter(|r| &step.means[r * 3..r * 3 + 3] == first_mean)
        .count() as f64
        / rows as f64;
    assert!(
        (share - 0.5).abs() < 0.02,
        "elite shares {share:.3} / {:.3}",
        1.0 - share
    );

    // The samples are the two-elite mixture the step reports (each row's
    // mean and σ): its mean and variance, computed from those terms.
    let truth = true_mean(&s, a);
    for d in 0..3 {
        let column =
            |v: &[f32]| -> Vec<f64> { (0..rows).map(|r| f64::from(v[r * 3 + d])).collect() };
        let (samples, means, sigma) = (
            column(&step.next_states),
            column(&step.means),
            column(&step.sigma),
        );
        let average = |v: &[f64]| v.iter().sum::<f64>() / rows as f64;
        let mixture_mean = average(&means);
        let second: Vec<f64> = sigma
            .iter()
            .zip(&means)
            .map(|(s, m)| s * s + m * m)
            .collect();
        let mixture_var = average(&second) - mixture_mean * mixture_mean;
        let mean = average(&samples);
        let centred: Vec<f64> = samples.iter().map(|x| (x - mean).powi(2)).collect();
        let var = average(&centred);
        let standard_error = (mixture_var / rows as f64).sqrt();
        assert!(
            (mean - mixture_mean).abs() < 4.0 * standard_error,
            "output {d}: mean {mean} vs {mixture_mean}"
        );
        assert!(
            (var / mixture_var - 1.0).abs() < 0.05,
            "output {d}: variance {var} vs {mixture_var}"
        );
        // ... and near the system itself (a short fit: within half the noise).
        let noise = f64::from(NOISE[d]);
        let change = mean - f64::from(states[d]);
        assert!(
            (change - f64::from(truth[d])).abs() < 0.5 * noise,
            "output {d}: mean change {change:.4} vs {}",
            truth[d]
        );
        assert!(
            (var.sqrt() / noise - 1.0).abs() < 0.5,
            "output {d}: std {:.4} vs noise {noise}",
            var.sqrt()
        );
    }

    // MOPO's η is the largest member's ‖σ‖, about the noise's norm here;
    // TATU's disagreement between members is a fraction of it on the data.
    let noise_norm = NOISE.iter().map(|n| n * n).sum::<f32>().sqrt();
    assert!(
        step.eta.iter().all(|&e| (e / noise_norm - 1.0).abs() < 0.5),
        "η {} vs ‖noise‖ {noise_norm}",
        step.eta[0]
    );
    let largest = (0..rows)
        .map(|r| {
            step.sigma[r * 3..r * 3 + 3]
                .iter()
                .map(|x| x * x)
                .sum::<f32>()
                .sqrt()
        })
        .fold(0.0, f32::max);
    assert!(step.eta[0] >= largest - 1e-6, "η covers every elite's ‖σ‖");
    let disagreement = dynamics
        .with_uncertainty(EnsembleUncertainty::MaxDisagreement)
        .step(&states[..3], &actions[..1], &noise[..4])
        .eta[0];
    assert!(
        disagreement < 0.5 * noise_norm,
        "disagreement {disagreement} on the data"
    );
    assert!(step.h_eta.iter().all(|&h| h == 0.0));
}

#[test]
fn a_saved_ensemble_loads_to_the_same_steps_and_refuses_damage() {
    use nuno::agent::PortableActor;
    use nuno::data::{GenerateConfig, generate};
    use nuno::envs::{System, TaskConfig, TaskName};
    let task = TaskConfig::d4rl(TaskName::Hopper);
    let policy = PortableActor::rlkit_random(11, 3, &[32, 32], 0);
    let hopper = generate(
        &GenerateConfig::new(task.clone(), "random", 1000, 0),
        &policy,
        "test",
        &|_| {},
    )
    .unwrap();
    let config = small_config().with_max_epochs(Some(2));
    let fit = fit_ensemble(
        &hopper,
        &config,
        Kernel::Fused,
        &Device::flex(),
        None,
        &mut |_| Ok(()),
    )
    .unwrap();
    let dir = tempfile::tempdir().unwrap();
    // The synthetic system's ensemble does not fit hopper's widths.
    let error = nuno::artifact::save_ensemble(
        dir.path(),
        &fitted(),
        &small_config(),
        &System::Task(task.clone()),
        None,
    )
    .unwrap_err()
    .to_string();
    assert!(error.contains("takes 3 inputs"), "{error}");
    let saved =
        nuno::artifact::save_ensemble(dir.path(), &fit, &config, &System::Task(task.clone()), None)
            .unwrap();
    assert_eq!(
        (saved.kind.as_str(), saved.obs_dim, saved.act_dim),
        ("gaussian-ensemble", 11, 3)
    );

    let (loaded, _) = nuno::artifact::load_ensemble(dir.path(), &Device::flex()).unwrap();
    assert_eq!(loaded.elites, fit.elites);
    let n = 5;
    let states: Vec<f32> = hopper
        .observations
        .rows()
        .into_iter()
        .take(n)
        .flat_map(|r| r.iter().copied().chain([0.0]).collect::<Vec<_>>())
        .collect();
    let actions: Vec<f32> = hopper
        .actions
        .rows()
        .into_iter()
        .take(n)
        .flat_map(|r| r.to_vec())
        .collect();
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let noise: Vec<f32> = (0..n * 13).map(|_| rng.sample(StandardNormal)).collect();
    let step = |f: &EnsembleFit| {
        EnsembleDynamics::new(f, 11, 3, EnsembleUncertainty::MaxAleatoric)
            .step(&states, &actions, &noise)
    };
    assert_eq!(step(&loaded), step(&fit));

    // The one model-folder loader reads it as an ensemble of its task, stepping
    // as the ensemble does on either kernel; a folder of neither kind is named.
    let folder = nuno::artifact::ModelFolder::load(dir.path(), &Device::flex()).unwrap();
    assert!(matches!(
        folder,
        nuno::artifact::ModelFolder::GaussianEnsemble { .. }
    ));
    assert_eq!(folder.system().unwrap(), Some(System::Task(task.clone())));
    for kernel in [nuno::infer::Kernel::Burn, nuno::infer::Kernel::Fused] {
        let stepped = folder.dynamics(kernel).step(&states, &actions, &noise);
        for (a, b) in stepped.next_states.iter().zip(&step(&fit).next_states) {
            assert!((a - b).abs() < 1e-4, "{kernel:?}: {a} against {b}");
        }
    }
    let empty = tempfile::tempdir().unwrap();
    let error = nuno::artifact::ModelFolder::load(empty.path(), &Device::flex())
        .err()
        .unwrap()
        .to_string();
    assert!(
        error.contains("not a model folder")
            && error.contains("model.json")
            && error.contains("ensemble.json"),
        "{error}"
    );

    // A flipped byte in the weights, or elites the members cannot have.
    let weights = dir.path().join("ensemble.safetensors");
    let mut bytes = std::fs::read(&weights).unwrap();
    let last = bytes.len() - 1;
    bytes[last] ^= 1;
    std::fs::write(&weights, &bytes).unwrap();
    let error = nuno::artifact::load_ensemble(dir.path(), &Device::flex())
        .unwrap_err()
        .to_string();
    assert!(error.contains("not the ones"), "{error}");
    bytes[last] ^= 1;
    std::fs::write(&weights, &bytes).unwrap();
    let path = dir.path().join("ensemble.json");
    let mut metadata: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    metadata["elites"] = serde_json::json!([0, 9]);
    std::fs::write(&path, metadata.to_string()).unwrap();
    let error = nuno::artifact::load_ensemble(dir.path(), &Device::flex())
        .unwrap_err()
        .to_string();
    assert!(error.contains("elites"), "{error}");
}

/// TATU's disagreement from the members' centre, MOReL's largest pairwise
/// discrepancy (both over the observation only) and MOPO's ‖σ‖, each by hand
/// from every member's own prediction.
#[test]
fn tatu_truncates_on_the_members_disagreement_over_the_observation_only() {
    let fit = fitted();
    let dynamics = EnsembleDynamics::new(&fit, 2, 1, EnsembleUncertainty::MaxAleatoric)
        .with_truncation_signal(EnsembleUncertainty::MaxDisagreement);
    // Points on and off the data (far actions make the members disagree).
    let points = [
        ([0.4f32, -0.3], 0.5f32),
        ([0.1, 0.2], -0.2),
        ([3.0, -2.5], 6.0),
    ];
    let states: Vec<f32> = points.iter().flat_map(|(s, _)| [s[0], s[1], 0.0]).collect();
    let actions: Vec<f32> = points.iter().map(|&(_, a)| a).collect();
    let step = dynamics.step(&states, &actions, &[0.0; 12]);
    let signal = step.truncation_signal.as_ref().expect("a TATU signal");
    let pairwise = dynamics
        .with_truncation_signal(EnsembleUncertainty::MaxPairwise)
        .step(&states, &actions, &[0.0; 12])
        .truncation_signal
        .expect("a MOReL signal");

    // By hand from every member's own prediction: means of (Δs₀, Δs₁, r).
    let device = Device::flex();
    for (r, (s, a)) in points.iter().enumerate() {
        let x: Vec<f32> = [s[0], s[1], *a]
            .iter()
            .zip(fit.scaler.mean.iter().zip(&fit.scaler.std))
            .map(|(v, (m, d))| (v - m) / d)
            .collect();
        let x = Tensor::<2>::from_data(TensorData::new(x, [1, 3]), &device);
        let members: Vec<(Vec<f32>, Vec<f32>)> = (0..fit.model.members.len())
            .map(|m| {
                let (mean, logvar) = fit.model.member(m, x.clone());
                (to_f32_vec(mean), to_f32_vec((logvar * 0.5).exp()))
            })
            .collect();
        let n = members.len() as f64;
        let centre: Vec<f64> = (0..2)
            .map(|d| members.iter().map(|(m, _)| f64::from(m[d])).sum::<f64>() / n)
            .collect();
        let disagreement = members
            .iter()
            .map(|(m, _)| {
                (0..2)
                    .map(|d| (f64::from(m[d]) - centre[d]).powi(2))
                    .sum::<f64>()
                    .sqrt()
            })
            .fold(0.0, f64::max);
        let aleatoric = members
            .iter()
            .map(|(_, std)| std.iter().map(|v| f64::from(v * v)).sum::<f64>().sqrt())
            .fold(0.0, f64::max);
        let mut largest_pair = 0.0f64;
        for (i, (a, _)) in members.iter().enumerate() {
            for (b, _) in &members[i + 1..] {
                let d = (0..2)
                    .map(|d| (f64::from(a[d]) - f64::from(b[d])).powi(2))
                    .sum::<f64>()
                    .sqrt();
                largest_pair = largest_pair.max(d);
            }
        }
        assert!(
            (f64::from(pairwise[r]) - largest_pair).abs() < 1e-4 * largest_pair.max(1e-3),
            "point {r}: pairwise {} vs {largest_pair}",
            pairwise[r]
        );
        assert!(
            (f64::from(signal[r]) - disagreement).abs() < 1e-4 * disagreement.max(1e-3),
            "point {r}: signal {} vs disagreement {disagreement}",
            signal[r]
        );
        assert!(
            (f64::from(step.eta[r]) - aleatoric).abs() < 1e-4 * aleatoric,
            "point {r}: η {} vs MOPO's {aleatoric}",
            step.eta[r]
        );
    }
    assert!(
        signal[2] > 5.0 * signal[0],
        "far off the data the members disagree more: {signal:?}"
    );
}

#[test]
fn the_fused_path_steps_the_ensemble_as_burn_does() {
    let fit = fitted();
    let burn = EnsembleDynamics::new(&fit, 2, 1, EnsembleUncertainty::MaxAleatoric)
        .with_truncation_signal(EnsembleUncertainty::MaxDisagreement);
    let fused = burn.on_fused_path();
    // Enough rows for several tiles per member, on and off the data.
    let rows = 700;
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    let states: Vec<f32> = (0..rows)
        .flat_map(|_| {
            [
                rng.random_range(-3.0..3.0),
                rng.random_range(-3.0..3.0),
                0.0,
            ]
        })
        .collect();
    let actions: Vec<f32> = (0..rows).map(|_| rng.random_range(-4.0..4.0)).collect();
    let noise: Vec<f32> = (0..rows * 4).map(|_| rng.sample(StandardNormal)).collect();
    let (a, b) = (
        burn.step(&states, &actions, &noise),
        fused.step(&states, &actions, &noise),
    );
    let close = |name: &str, x: &[f32], y: &[f32]| {
        assert_eq!(x.len(), y.len(), "{name}");
        for (i, (u, v)) in x.iter().zip(y).enumerate() {
            assert!(
                (u - v).abs() <= 1e-4 * u.abs().max(1.0),
                "{name}[{i}]: burn {u}, fused {v}"
            );
        }
    };
    close("next_states", &a.next_states, &b.next_states);
    close("means", &a.means, &b.means);
    close("sigma", &a.sigma, &b.sigma);
    close("eta", &a.eta, &b.eta);
    close(
        "truncation_signal",
        a.truncation_signal.as_ref().unwrap(),
        b.truncation_signal.as_ref().unwrap(),
    );
}

/// MOBILE's penalty with a known "critic" (the next state's first
/// coordinate): u is the unbiased std over the two elites of their sample
/// means, so about |m₁ − m₂|/√2 for the elites' mean next states m_e, which
/// the ensemble's own step reports when its member column picks each elite;
/// only the model rows lose β·u.
#[test]
fn mobiles_penalty_is_the_elites_spread_of_the_next_value() {
    let fit = fitted();
    let dynamics =
        EnsembleDynamics::new(&fit, 2, 1, EnsembleUncertainty::MaxAleatoric).on_fused_path();
    assert_eq!(dynamics.elite_count(), 2);
    // Off the data (s ∈ [−1, 1]²), where the elites disagree.
    let (s, a) = ([8.0f32, -8.0], 3.0f32);
    let elite = |z: f32| dynamics.step(&[s[0], s[1], 0.0], &[a], &[0.0, 0.0, 0.0, z]);
    let (first, second) = (elite(-3.0), elite(3.0));
    let expected = (first.means[0] - second.means[0]).abs() / 2f32.sqrt();
    let samples = 20_000;
    let spread = (first.sigma[0].powi(2) + second.sigma[0].powi(2)).sqrt();
    let tolerance = 4.0 * spread / (samples as f32).sqrt() / 2f32.sqrt();
    assert!(
        expected > 10.0 * tolerance,
        "the elites must disagree: {expected}"
    );

    let mut batch = nuno::shared::TransitionBatch {
        observations: vec![0.1, 0.2, s[0], s[1]],
        actions: vec![0.3, a],
        rewards: vec![1.0, 1.0],
        next_observations: vec![0.0; 4],
        terminals: vec![0.0, 0.0],
    };
    let term = nuno::agent::BellmanPenalty::new(3.0).with_samples(samples);
    let mut first_coordinate =
        |next: &[f32], _: &mut ChaCha8Rng| next.chunks_exact(2).map(|row| row[0]).collect();
    let u = term.penalize(
        &mut batch,
        1,
        &dynamics,
        &mut first_coordinate,
        &mut ChaCha8Rng::seed_from_u64(9),
    );
    assert!(
        (u - expected).abs() < tolerance,
        "u {u} vs {expected} ± {tolerance}"
    );
    assert_eq!(batch.rewards[0], 1.0, "a real row keeps its reward");
    assert!((batch.rewards[1] - (1.0 - 3.0 * u)).abs() < 1e-5);
}

/// RAMBO's adversarial update: the drawn transition's log-likelihood is the
/// elites' Gaussian mixture's, by hand from the means and σ the ensemble's own
/// step reports for each elite; one step with a positive advantage makes the
/// drawn transition less likely, with a negative one more likely (the
/// adversarial term's sign), the supervised term present in both; on either kernel.
#[test]
fn rambos_adversarial_step_lowers_the_likelihood_of_what_the_policy_values() {
    for kernel in [Kernel::Burn, Kernel::Fused] {
        adversarial_step_lowers_the_likelihood_of_what_the_policy_values(kernel);
    }
}

fn adversarial_step_lowers_the_likelihood_of_what_the_policy_values(kernel: Kernel) {
    let fit = fitted();
    let dynamics = EnsembleDynamics::new(&fit, 2, 1, EnsembleUncertainty::MaxAleatoric);
    let config = AdversarialConfig::new(1e3).with_learning_rate(1e-3);
    let device = Device::flex();
    let (obs, actions) = (vec![0.4f32, -0.3, -0.2, 0.5], vec![0.5f32, -0.7]);
    let mut adversary = AdversarialEnsemble::new(&dynamics, config.clone(), kernel, &device);
    let sample = adversary.sample(&obs, &actions, &mut ChaCha8Rng::seed_from_u64(3));

    // By hand: ln((1/2)·Σ_e Π_d N(x_d | m_e,d, σ_e,d)), each elite's m and σ
    // from the step with no noise and its member column (Φ(∓3) picks each).
    let by_hand = |dynamics: &EnsembleDynamics, state: [f32; 3], action: f32, x: [f32; 3]| {
        let densities: Vec<f64> = [-3.0f32, 3.0]
            .iter()
            .map(|&z| {
                let step = dynamics.step(&state, &[action], &[0.0, 0.0, 0.0, z]);
                (0..3)
                    .map(|d| {
                        let (m, s) = (f64::from(step.means[d]), f64::from(step.sigma[d]));
                        let u = (f64::from(x[d]) - m) / s;
                        (-0.5 * u * u).exp() / (s * (2.0 * std::f64::consts::PI).sqrt())
                    })
                    .product()
            })
            .collect();
        (0.5 * densities.iter().sum::<f64>()).ln()
    };
    let close = |ours: f32, hand: f64| (f64::from(ours) - hand).abs() < 1e-3 * hand.abs().max(1.0);
    for r in 0..2 {
        let state = [obs[2 * r], obs[2 * r + 1], 0.0];
        let next = &sample.next_observations[2 * r..2 * r + 2];
        let x = [next[0], next[1], sample.rewards[r]];
        let (ours, hand) = (
            sample.log_probs()[r],
            by_hand(&dynamics, state, actions[r], x),
        );
        assert!(close(ours, hand), "{kernel}, row {r}: {ours} vs {hand}");
    }

    // One row, one step each way; the real batch is a dataset-like transition.
    let real = (
        &obs[..2],
        &actions[..1],
        &[0.55f32, -0.36][..],
        &[0.9f32][..],
    );
    for advantage in [1.0f32, -1.0] {
        let mut adversary = AdversarialEnsemble::new(&dynamics, config.clone(), kernel, &device);
        let sample = adversary.sample(&obs[..2], &actions[..1], &mut ChaCha8Rng::seed_from_u64(4));
        let (next, reward) = (sample.next_observations.clone(), sample.rewards.clone());
        let before = sample.log_probs()[0];
        adversary.step(&sample, &[advantage], real);
        let after = adversary.log_prob(&obs[..2], &actions[..1], &next, &reward)[0];
        // The stepped ensemble, handed back as dynamics, steps with the new weights.
        let stepped = adversary.dynamics(&dynamics);
        let hand = by_hand(
            &stepped,
            [obs[0], obs[1], 0.0],
            actions[0],
            [next[0], next[1], reward[0]],
        );
        assert!(close(after, hand), "{kernel}, stepped: {after} vs {hand}");
        assert!(
            (after - before) * advantage < 0.0,
            "{kernel}, A = {advantage}: log p {before} → {after}"
        );
    }
}

/// RAMBO's adversarial step on the fused kernels is burn's autodiff's: from
/// the same ensemble, the same drawn transitions (both kernels draw them alike),
/// advantage and real batch, three steps each leave both losses, every weight
/// and bound, and Adam's moments within float rounding of each other; the
/// adversarial term moves the weights far more than that (with A = 0 the
/// fused step ends elsewhere), so a fused step without it could not pass.
#[test]
fn rambos_fused_adversarial_step_follows_burns_autodiff() {
    let fit = fitted();
    let dynamics = EnsembleDynamics::new(&fit, 2, 1, EnsembleUncertainty::MaxAleatoric);
    let config = AdversarialConfig::new(10.0).with_learning_rate(1e-3);
    let device = Device::flex();
    let data = linear_gaussian(32, 5);
    let (obs, actions) = (
        data.observations.as_slice().unwrap(),
        data.actions.as_slice().unwrap(),
    );
    let real = (
        &obs[..32],
        &actions[..16],
        &data.next_observations.as_slice().unwrap()[..32],
        &data.rewards.as_slice().unwrap()[..16],
    );
    let (starts, start_actions) = (&obs[32..], &actions[16..]);
    let mut rng = ChaCha8Rng::seed_from_u64(6);
    let advantage: Vec<f32> = (0..16).map(|_| rng.sample(StandardNormal)).collect();
    let adversary = |kernel| AdversarialEnsemble::new(&dynamics, config.clone(), kernel, &device);
    let (mut burn, mut fused) = (adversary(Kernel::Burn), adversary(Kernel::Fused));
    let sample = burn.sample(starts, start_actions, &mut ChaCha8Rng::seed_from_u64(7));
    let fused_sample = fused.sample(starts, start_actions, &mut ChaCha8Rng::seed_from_u64(7));
    let drawn = |s: &nuno::ensemble::AdversarialSample| {
        let mut all = s.next_observations.clone();
        all.extend(&s.rewards);
        all.extend(s.log_probs());
        all
    };
    let worst = largest_difference(&drawn(&sample), &drawn(&fused_sample));
    assert!(worst < 1e-4, "the kernels draw apart: {worst}");
    for step in 0..3 {
        let (b, f) = (
            burn.step(&sample, &advantage, real),
            fused.step(&sample, &advantage, real),
        );
        for (what, b, f) in [
            ("adversarial", b.adversarial, f.adversarial),
            ("supervised", b.supervised, f.supervised),
        ] {
            assert!(
                (b - f).abs() <= 1e-4 * b.abs().max(1.0),
                "step {step}, {what}: burn {b}, fused {f}"
            );
        }
    }
    let (b, f) = (params(&burn.model()), params(&fused.model()));
    let worst = largest_difference(&b, &f);
    assert!(worst < 1e-5, "largest parameter difference {worst}");
    let (burn_adam, fused_adam) = (burn.optimizer_state(), fused.optimizer_state());
    assert_eq!(burn_adam.time, fused_adam.time);
    assert_eq!(burn_adam.moments.len(), fused_adam.moments.len());
    for (path, bm) in &burn_adam.moments {
        // Gradients scale with w_adv: relative to the largest moment.
        let worst = largest_difference(&bm.first, &fused_adam.moments[path].first);
        let scale = bm.first.iter().fold(1e-3f32, |m, v| m.max(v.abs()));
        assert!(
            worst < 1e-4 * scale,
            "{path}: first moments {worst} apart (largest {scale})"
        );
    }
    let mut blind = adversary(Kernel::Fused);
    for _ in 0..3 {
        blind.step(&sample, &[0.0; 16], real);
    }
    let moved = largest_difference(&params(&blind.model()), &f);
    assert!(
        moved > 100.0 * 1e-5,
        "the adversarial term moved the weights by only {moved}"
    );
}
