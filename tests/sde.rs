//! The neural SDE: kinematic prior, η on toy data (Appendix B.2), fit quality
//! on hopper against the constant-velocity predictor, thresholds, η's report on
//! the shipped model, and the artifact round trip (Rust and Python's safetensors).

mod common;

use std::path::Path;

use burn::module::{Module, ModuleMapper, Param};
use burn::tensor::{Device, Tensor, TensorData};
use nuno::agent::PortableActor;
use nuno::artifact::{
    ArtifactError, DynamicsProvenance, collect_tensors, load_dynamics, save_dynamics,
};
use nuno::data::{Dataset, GenerateConfig, NormalizerConfig, generate};
use nuno::envs::{MujocoTask, TaskConfig, TaskName};
use nuno::nn::seeded_init;
use nuno::sde::{
    CalibrationConfig, DriftInputs, DynamicsSpec, EtaReportConfig, FitConfig, LikelihoodPath,
    LossConfig, NeuralSde, PhysicalScales, SdeConfig, SdeError, ThresholdConfig, Z_STD_BAND, auroc,
    calibration_report, compute_thresholds, cvar, eta_report, fit, fit_eta, prediction_error,
    window_tensors,
};
use nuno::shared::BatchPolicy;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn hopper_spec() -> DynamicsSpec {
    let task = MujocoTask::new(&TaskConfig::d4rl(TaskName::Hopper)).unwrap();
    DynamicsSpec {
        obs_dim: task.obs_dim(),
        act_dim: task.act_dim(),
        split: task.state_split(),
        dt: task.dt(),
    }
}

fn hopper_dataset(transitions: usize, seed: u64) -> Dataset {
    let task = TaskConfig::d4rl(TaskName::Hopper);
    let policy = PortableActor::rlkit_random(11, 3, &[64, 64], seed);
    generate(
        &GenerateConfig::new(task, "random", transitions, seed),
        &policy,
        "test",
        &|_| {},
    )
    .unwrap()
}

/// A behaviour policy with a narrow action distribution (a fixed push plus a
/// little noise), so that uniform random actions are out of distribution.
struct NarrowPolicy;

impl BatchPolicy for NarrowPolicy {
    fn obs_dim(&self) -> usize {
        11
    }
    fn act_dim(&self) -> usize {
        3
    }
    fn act(&self, observations: &[f32], rng: &mut dyn rand::RngCore) -> Vec<f32> {
        let rows = observations.len() / 11;
        (0..rows * 3)
            .map(|i| [0.4, -0.3, 0.2][i % 3] + 0.1 * rng.random_range(-1.0f32..1.0))
            .collect()
    }
}

/// A freshly initialised small hopper model with scales measured on `dataset`.
fn untrained_hopper_model(dataset: &Dataset, device: &Device) -> NeuralSde {
    let scales = PhysicalScales::measure(dataset, &hopper_spec(), &NormalizerConfig::default());
    seeded_init(device, 0, || {
        NeuralSde::init(hopper_spec(), scales, small_config(1).model, device)
    })
}

/// Small networks so fits finish in seconds on two cores.
fn small_config(steps: usize) -> FitConfig {
    let mut model = SdeConfig::new();
    model.drift_hidden = vec![64, 64];
    model.sigma_hidden = vec![64, 64];
    let mut config = FitConfig::new(model, LossConfig::new());
    config.max_steps = steps;
    config.eval_every = 100;
    config.patience = 100;
    config.valid_windows = 512;
    config
}

fn tensor(values: Vec<f32>, shape: [usize; 2]) -> Tensor<2> {
    Tensor::from_data(TensorData::new(values, shape), &Device::flex())
}

fn to_vec(t: Tensor<2>) -> Vec<f32> {
    t.into_data().convert::<f32>().try_to_vec().unwrap()
}

/// Zeroes every parameter under the drift networks G, H and f_res.
struct ZeroDrift {
    path: Vec<String>,
}

impl ModuleMapper for ZeroDrift {
    fn enter_module(&mut self, name: &str, _: &str) {
        self.path.push(name.into());
    }
    fn exit_module(&mut self, _: &str, _: &str) {
        self.path.pop();
    }
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        if ["g_net", "h_net", "res_net"].contains(&self.path[0].as_str()) {
            param.map(|t| t.zeros_like())
        } else {
            param
        }
    }
}

#[test]
fn kinematic_prior_holds_exactly_in_physical_units() {
    let dataset = hopper_dataset(2000, 0);
    let spec = hopper_spec();
    let scales = PhysicalScales::measure(&dataset, &spec, &Default::default());
    let device = Device::flex();
    let model = seeded_init(&device, 0, || {
        NeuralSde::init(spec.clone(), scales, SdeConfig::new(), &device)
    })
    .map(&mut ZeroDrift { path: vec![] });
    let rows: Vec<usize> = (0..64).map(|i| i * 31).collect();
    let states: Vec<f32> = rows
        .iter()
        .flat_map(|&i| dataset.observations.row(i).to_vec())
        .collect();
    let actions: Vec<f32> = rows
        .iter()
        .flat_map(|&i| dataset.actions.row(i).to_vec())
        .collect();
    let zero_noise = tensor(vec![0.0; 64 * 11], [64, 11]);
    let (next, terms) = model.step(
        tensor(states.clone(), [64, 11]),
        tensor(actions, [64, 3]),
        zero_noise,
    );
    let next = to_vec(next);
    let dt = spec.dt as f32;
    for b in 0..64 {
        let s = &states[b * 11..(b + 1) * 11];
        let n = &next[b * 11..(b + 1) * 11];
        for (&p, &v) in spec
            .split
            .positions
            .iter()
            .zip(&spec.split.position_velocity)
        {
            assert_eq!(n[p], s[p] + s[v] * dt, "row {b} position {p}");
        }
        for &v in &spec.split.velocities {
            assert_eq!(n[v], s[v], "row {b} velocity {v}");
        }
    }
    // The diffusion is positive and η lies in (0, η_max).
    assert!(to_vec(terms.diffusion()).iter().all(|&d| d > 0.0));
    assert!(to_vec(terms.eta).iter().all(|&e| e > 0.0 && e < 1.0));
}

#[test]
fn eta_separates_toy_data_from_far_points() {
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let clusters: Vec<[f32; 2]> = (0..300)
        .map(|i| {
            let c = [[-2.0, -2.0], [2.0, -1.0], [0.0, 2.5]][i % 3];
            [
                c[0] + rng.random_range(-0.15..0.15),
                c[1] + rng.random_range(-0.15..0.15),
            ]
        })
        .collect();
    let ring: Vec<[f32; 2]> = (0..300)
        .map(|i| {
            let a = i as f32 / 300.0 * std::f32::consts::TAU;
            let r = 2.0 + rng.random_range(-0.05..0.05);
            [r * a.cos(), r * a.sin()]
        })
        .collect();
    let line: Vec<[f32; 2]> = (0..300)
        .map(|i| {
            let t = i as f32 / 299.0 * 4.0 - 2.0;
            [t, 0.5 * t + rng.random_range(-0.05..0.05)]
        })
        .collect();
    let device = Device::flex();
    // In two dimensions the far-field hinge is sound (a 300-point reference covers
    // the data densely): it lifts η inside the ring, where the local losses alone
    // leave it low. It needs λ_grad = 1 to keep η low on the data, and a small
    // weight: from λ_far ≈ 0.05 up it can saturate η on a whole cluster, where
    // the sigmoid is flat and nothing pulls η back down.
    let loss = LossConfig {
        lambda_far: 0.02,
        lambda_grad: 1.0,
        ..LossConfig::new()
    };
    let config = FitConfig {
        max_steps: 800,
        batch_size: 64,
        ..FitConfig::new(SdeConfig::new(), loss)
    };
    let radius = config.loss.radius;
    for (name, points) in [("clusters", clusters), ("ring", ring), ("line", line)] {
        let flat: Vec<f32> = points.iter().flatten().copied().collect();
        let eta = fit_eta(&flat, 2, &config, &device).unwrap();
        // Points at least 3r from every datum, on a grid over the data's
        // surroundings (the ring's interior included).
        let far: Vec<f32> = (0..41 * 41)
            .map(|i| [(i % 41) as f32 * 0.2 - 4.0, (i / 41) as f32 * 0.2 - 4.0])
            .filter(|q| {
                points
                    .iter()
                    .all(|p| ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt() >= 3.0 * radius)
            })
            .flatten()
            .collect();
        let on_data = to_vec(eta.eta(tensor(flat.clone(), [points.len(), 2])));
        let off_data = to_vec(eta.eta(tensor(far.clone(), [far.len() / 2, 2])));
        // Measured with the initialisation isolated (`seeded_init`): seed 0 gives
        // clusters 1.0, ring 0.998, line 0.984 (the line's ends); seeds 1–3 ≥ 0.9998.
        let score = auroc(&off_data, &on_data);
        assert!(score >= 0.98, "{name}: AUROC {score}");
        let mean_on = on_data.iter().sum::<f32>() / on_data.len() as f32;
        let max_off = off_data.iter().copied().fold(0.0, f32::max);
        assert!(mean_on < 0.35, "{name}: η on data {mean_on}");
        assert!(
            max_off <= 1.0 && max_off > 0.9,
            "{name}: η far away {max_off} (bounded by η_max = 1)"
        );
    }
}

#[test]
fn loss_settings_no_fit_can_use_are_refused_by_name() {
    let device = Device::flex();
    let points = [0.0f32, 1.0, 2.0, 3.0];
    let with = |loss: LossConfig| FitConfig::new(SdeConfig::new(), loss);
    let cases = [
        (
            LossConfig {
                lambda_far: 0.1,
                far_target: 1.0,
                ..LossConfig::new()
            },
            "far_target = 1",
        ),
        (
            LossConfig {
                radius: 0.0,
                ..LossConfig::new()
            },
            "radius = 0",
        ),
        (
            LossConfig {
                lambda_sc: f32::NAN,
                ..LossConfig::new()
            },
            "lambda_sc = NaN",
        ),
    ];
    for (loss, named) in cases {
        let err = fit_eta(&points, 2, &with(loss), &device).unwrap_err();
        assert!(err.to_string().contains(named), "{err} should name {named}");
    }
    let err = fit_eta(&points[..3], 2, &with(LossConfig::new()), &device).unwrap_err();
    assert!(err.to_string().contains("width 2"), "{err}");
}

#[test]
fn model_settings_no_fit_can_use_are_refused_by_name_before_fitting() {
    let dataset = hopper_dataset(300, 4);
    let (train, valid) = dataset.split_by_trajectory(0.3, 0);
    let device = Device::flex();
    let cases = [
        (vec![1.0, 2.0], "w_max has 2 values"),
        (vec![0.0], "w_max value 0"),
        (vec![-1.0; 11], "w_max value -1"),
        (vec![f32::INFINITY], "w_max value inf"),
    ];
    for (w_max, named) in cases {
        let mut config = small_config(1);
        config.model.w_max = w_max;
        let err = fit(&train, &valid, hopper_spec(), &config, &device, &mut |_| {
            panic!("fitting started")
        })
        .unwrap_err();
        assert!(err.to_string().contains(named), "{err} should name {named}");
    }
    // NUNO^R integrates one more dimension (r_c): 12 values fit it, 11 do not.
    let mut config = small_config(1);
    config.model.reward_model = true;
    config.model.w_max = vec![0.5; 11];
    let err = fit(&train, &valid, hopper_spec(), &config, &device, &mut |_| {}).unwrap_err();
    assert!(
        err.to_string().contains("one per state dimension (12)"),
        "{err}"
    );
}

#[test]
fn fit_schedules_no_fit_can_follow_are_refused_by_name_before_fitting() {
    let dataset = hopper_dataset(300, 4);
    let (train, valid) = dataset.split_by_trajectory(0.3, 0);
    let device = Device::flex();
    type Break = fn(&mut FitConfig);
    let cases: [(Break, &str); 5] = [
        (|c| c.h_bias_every = 0, "h_bias_every = 0"),
        (|c| c.eval_every = 0, "eval_every = 0"),
        (|c| c.log_every = 0, "log_every = 0"),
        (|c| c.eta_lr = Some(0.0), "eta_lr = 0"),
        (|c| c.eta_lr = Some(f64::NAN), "eta_lr = NaN"),
    ];
    for (break_it, named) in cases {
        let mut config = small_config(10);
        break_it(&mut config);
        let err = fit(&train, &valid, hopper_spec(), &config, &device, &mut |_| {
            panic!("fitting started")
        })
        .unwrap_err();
        assert!(err.to_string().contains(named), "{err} should name {named}");
    }
}

#[test]
fn hopper_fit_beats_constant_velocity_and_flags_random_actions() {
    let NarrowFit {
        model,
        summary,
        records,
        valid,
        ..
    } = narrow_hopper_fit(1500);
    let device = Device::flex();
    let config = small_config(1500);
    assert_eq!(summary.steps, 1500);
    assert!(
        summary.best_valid_nll < records[0].losses.data,
        "validation NLL never improved on the first loss"
    );
    assert_eq!(records.len(), 1500 / config.log_every);

    let errors = prediction_error(&model, &valid, 10, 512, 0, &device);
    let at = |h: usize| errors.iter().find(|e| e.horizon == h).unwrap();
    for h in [1, 10] {
        let e = at(h);
        assert!(
            e.model_rmse < e.constant_velocity_rmse,
            "horizon {h}: model RMSE {} vs constant velocity {}",
            e.model_rmse,
            e.constant_velocity_rmse
        );
    }

    // Figure 3's property: η is higher for random actions than for the dataset's.
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let rows: Vec<usize> = (0..512).map(|_| rng.random_range(0..valid.len())).collect();
    let states: Vec<f32> = rows
        .iter()
        .flat_map(|&i| valid.observations.row(i).to_vec())
        .collect();
    let data_actions: Vec<f32> = rows
        .iter()
        .flat_map(|&i| valid.actions.row(i).to_vec())
        .collect();
    let random_actions: Vec<f32> = (0..512 * 3).map(|_| rng.random_range(-1.0..1.0)).collect();
    let mean_eta = |actions: Vec<f32>| {
        let input =
            model.normalized_input(tensor(states.clone(), [512, 11]), tensor(actions, [512, 3]));
        let eta = to_vec(model.distance.eta(input));
        eta.iter().sum::<f32>() / eta.len() as f32
    };
    let (on_data, random) = (mean_eta(data_actions), mean_eta(random_actions));
    assert!(random > on_data, "η random {random} vs dataset {on_data}");

    // Thresholds: non-decreasing in α, and the maximum at α = 1.
    let thresholds = compute_thresholds(
        &model,
        &valid,
        &ThresholdConfig {
            max_windows: 128,
            ..ThresholdConfig::new()
        },
        &device,
    )
    .unwrap();
    assert!(
        thresholds.get(5, 0.9).is_some(),
        "h = 5 windows exist in the validation data"
    );
    for (i, &h) in thresholds.horizons.iter().enumerate() {
        // Horizons longer than every trajectory have no window, hence no threshold.
        let Some(row) = thresholds.values[i]
            .iter()
            .copied()
            .collect::<Option<Vec<f32>>>()
        else {
            assert_eq!(thresholds.windows[i], 0);
            continue;
        };
        assert!(
            row.windows(2).all(|w| w[0] <= w[1] + 1e-6),
            "h {h}: {row:?}"
        );
        assert!(
            row[row.len() - 1] <= h as f32,
            "accumulated η is bounded by h·η_max"
        );
    }
    assert_eq!(thresholds.get(5, 1.0), thresholds.values[0][4]);
}

/// Every dimension's z std at most the band's top, and ±2Σ covering at least
/// 80 % (a Gaussian's 95.4 %; hopper's joint velocities have heavier tails).
/// The floor is where the fit lies over seeds, not one seed's value: the
/// narrow fit's worst dimension held 84–97 % over fit seeds 0–3 with either
/// optimiser path (burn's Adam, `nn::Adam`; equal to 1e-7 for 60 steps, apart
/// by rounding after 1500), the shipped model 91 %. A Σ half as wide as the
/// errors would hold about 68 %.
fn assert_not_overconfident(report: &nuno::sde::CalibrationReport, summary: &str) {
    for (d, c) in report.dimensions.iter().enumerate() {
        assert!(c.z_std <= Z_STD_BAND.1, "dim {d}: {summary}");
        assert!(c.within_two >= 0.80, "dim {d}: {summary}");
    }
}

/// The narrow-action hopper data (20k transitions, 20 % of trajectories held
/// out) fitted with small networks, and how the fit went.
struct NarrowFit {
    model: NeuralSde,
    summary: nuno::sde::FitSummary,
    records: Vec<nuno::sde::FitRecord>,
    dataset: Dataset,
    valid: Dataset,
}

fn narrow_hopper_fit(steps: usize) -> NarrowFit {
    narrow_hopper_fit_with(small_config(steps))
}

fn narrow_hopper_fit_with(config: FitConfig) -> NarrowFit {
    let task = TaskConfig::d4rl(TaskName::Hopper);
    let dataset = generate(
        &GenerateConfig::new(task, "narrow", 20_000, 1),
        &NarrowPolicy,
        "narrow",
        &|_| {},
    )
    .unwrap();
    let (train, valid) = dataset.split_by_trajectory(0.2, 0);
    let mut records = Vec::new();
    let (model, summary) = fit(
        &train,
        &valid,
        hopper_spec(),
        &config,
        &Device::flex(),
        &mut |r| records.push(r.clone()),
    )
    .unwrap();
    NarrowFit {
        model,
        summary,
        records,
        dataset,
        valid,
    }
}

#[test]
fn diffusion_is_calibrated_on_the_data_and_truncation_spares_it_but_not_random_actions() {
    let NarrowFit {
        model,
        dataset,
        valid,
        ..
    } = narrow_hopper_fit(1500);
    let device = Device::flex();
    // As fit-model does: thresholds over the whole dataset, report on held-out trajectories.
    let thresholds = compute_thresholds(
        &model,
        &dataset,
        &ThresholdConfig::new().with_max_windows(512),
        &device,
    )
    .unwrap();
    let report = calibration_report(
        &model,
        &valid,
        Some(&thresholds),
        0.1,
        &[(-1.0, 1.0); 3],
        &CalibrationConfig::new().with_rows(1000).with_windows(256),
        &device,
    )
    .unwrap();
    let summary = format!("{report:#?}");
    eprintln!("{summary}");
    // Σ is never overconfident on the data: every dimension's z std is at most the
    // band's top and ±2Σ holds most of the errors. It comes out mostly
    // over-dispersed instead (z std 0.44–1.29 over fit seeds 0–3, positions
    // lowest): eq. 6's second step sees the noise its first step sampled
    // (docs/paper-map.md, known gaps).
    assert_not_overconfident(&report, &summary);
    // h(η) adds little noise on the data ...
    assert!(report.h_share_at_median_eta <= 0.25, "{summary}");
    // ... but much more off the data.
    let far = report.diffusion_at(3.0).unwrap();
    assert!(far.ratio_to_data >= 3.0, "{summary}");
    // ε(10, 0.95) truncates rollouts on random actions, rarely those on the data's.
    let t = report.truncation(10, 0.95).unwrap();
    assert!(t.random_actions >= 0.5, "{summary}");
    assert!(t.dataset_actions <= 0.1, "{summary}");
}

#[test]
fn one_step_likelihoods_from_the_data_calibrate_sigma_better_than_the_particle_path() {
    // The same narrow-action fit with L_data's steps started from the previous
    // step's particle (eq. 6) and from the recorded state: from the data, Σ's
    // spread is nearer the real next states' (z std in [0.7, 1.4]) in far more
    // dimensions. Measured, in-band fraction data / particle: 91 % / 55 % on
    // the Intel Xeon (AVX-512), 73 % / 36 % on the AMD EPYC (AVX2). A small
    // fit's float rounding differs by CPU kind, so the claim asserted is the
    // comparison, with margin, not one machine's figure.
    let report = |likelihood| {
        let mut config = small_config(1500);
        config.loss.likelihood = likelihood;
        let NarrowFit { model, valid, .. } = narrow_hopper_fit_with(config);
        calibration_report(
            &model,
            &valid,
            None,
            0.1,
            &[(-1.0, 1.0); 3],
            &CalibrationConfig::new().with_rows(1000),
            &Device::flex(),
        )
        .unwrap()
    };
    let (particle, data) = (
        report(LikelihoodPath::Particle),
        report(LikelihoodPath::Data),
    );
    let summary = format!("particle path {particle:#?}\ndata path {data:#?}");
    assert!(
        data.z_std_in_band >= particle.z_std_in_band + 0.2,
        "{summary}"
    );
    assert!(data.z_std_in_band >= 0.6, "{summary}");
}

#[test]
fn calibration_z_scores_follow_an_independent_gaussian_reference() {
    // Data drawn from a model is calibrated for that model by construction: each
    // next state is mean + Σ·sqrt(dt)·ε with ε ~ N(0, 1), so the report's z must
    // follow the Gaussian's 0 / 1 / 68.3 % / 95.4 %, whatever the networks say.
    let source = hopper_dataset(2000, 6);
    let device = Device::flex();
    let model = untrained_hopper_model(&source, &device);
    let (trajectories, steps) = (500, 10);
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    let mut state: Vec<f32> = (0..trajectories)
        .flat_map(|t| source.observations.row(t).to_vec())
        .collect();
    // Per trajectory, its observations, actions and next observations in step order.
    let mut chains = vec![[Vec::new(), Vec::new(), Vec::new()]; trajectories];
    for _ in 0..steps {
        let actions: Vec<f32> = (0..trajectories * 3)
            .map(|_| rng.random_range(-1.0..1.0))
            .collect();
        let noise = nuno::nn::standard_normal(trajectories * 11, &mut rng);
        let next = nuno::shared::BatchDynamics::step(&model, &state, &actions, &noise).next_states;
        for (t, [obs, act, next_obs]) in chains.iter_mut().enumerate() {
            obs.extend_from_slice(&state[t * 11..(t + 1) * 11]);
            act.extend_from_slice(&actions[t * 3..(t + 1) * 3]);
            next_obs.extend_from_slice(&next[t * 11..(t + 1) * 11]);
        }
        state = next;
    }
    let n = trajectories * steps;
    let column = |k: usize, width: usize| {
        let values: Vec<f32> = chains.iter().flat_map(|c| c[k].clone()).collect();
        ndarray::Array2::from_shape_vec((n, width), values).unwrap()
    };
    let parts = nuno::data::DatasetParts {
        observations: column(0, 11),
        actions: column(1, 3),
        rewards: ndarray::Array1::zeros(n),
        next_observations: column(2, 11),
        terminals: vec![false; n],
        timeouts: (0..n).map(|i| i % steps == steps - 1).collect(),
        qpos: None,
        qvel: None,
        action_log_probs: None,
        metadata: Default::default(),
    };
    let synthetic = Dataset::from_parts(parts, Path::new("model samples")).unwrap();
    assert_eq!(synthetic.trajectories().len(), trajectories);
    let report_with = |config: &CalibrationConfig| {
        calibration_report(
            &model,
            &synthetic,
            None,
            0.1,
            &[(-1.0, 1.0); 3],
            config,
            &device,
        )
    };
    let report = report_with(&CalibrationConfig::new().with_rows(4000)).unwrap();
    assert_eq!(report.dimensions.len(), 11);
    for (d, c) in report.dimensions.iter().enumerate() {
        assert!(c.z_mean.abs() < 0.06, "dim {d}: {c:?}");
        assert!((c.z_std - 1.0).abs() < 0.05, "dim {d}: {c:?}");
        assert!((c.within_one - 0.683).abs() < 0.03, "dim {d}: {c:?}");
        assert!((c.within_two - 0.954).abs() < 0.02, "dim {d}: {c:?}");
    }
    assert_eq!(report.z_std_in_band, 1.0);
    assert!(
        report.horizons.is_empty(),
        "no thresholds, no truncation rates"
    );
    let err = report_with(&CalibrationConfig::new().with_windows(0)).unwrap_err();
    assert!(err.to_string().contains("windows = 0"), "{err}");
}

#[test]
fn a_particle_that_stops_being_finite_counts_as_eta_max_in_open_loop_rollouts() {
    let dataset = hopper_dataset(2000, 4);
    let device = Device::flex();
    let model = untrained_hopper_model(&dataset, &device);
    // Row 0 starts at a dataset state, row 1 at one with a NaN velocity.
    let mut starts = dataset.observations.row(0).to_vec();
    starts.extend(dataset.observations.row(0));
    starts[11 + 7] = f32::NAN;
    let actions = vec![0.1f32; 2 * 3 * 3];
    let plan = nuno::sde::OpenLoop {
        horizon: 3,
        particles: 1,
        noise_scale: 1.0,
    };
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let rollout = model.rollout_open_loop(&starts, &actions, plan, &mut rng, &device);
    let eta_max = model.constants.config.eta_max;
    assert!(
        rollout.eta[..3]
            .iter()
            .all(|&e| e.is_finite() && e < eta_max)
    );
    assert_eq!(rollout.eta[3..], [eta_max; 3]);
}

#[test]
fn cvar_is_the_mean_of_the_upper_tail() {
    let values: Vec<f32> = (1..=10).map(|v| v as f32).collect();
    assert_eq!(cvar(&values, 1.0), Some(10.0));
    // α = 0.9 over 10 values: VaR index floor(0.9·9) = 8, tail {9, 10}.
    assert_eq!(cvar(&values, 0.9), Some(9.5));
    assert_eq!(cvar(&values, 0.0), Some(5.5));
    // No values, no tail, whatever α.
    assert_eq!(cvar(&[], 0.9), None);
    assert_eq!(cvar(&[], 1.0), None);
    // NUNO's code: ε(h, α ≥ 1) = 1.1 × the maximum; below 1 the CVaR as before.
    let code = ThresholdConfig {
        max_margin: 1.1,
        ..ThresholdConfig::new()
    };
    assert_eq!(code.epsilon(&values, 1.0), Some(11.0));
    assert_eq!(code.epsilon(&values, 0.9), Some(9.5));
    assert_eq!(ThresholdConfig::new().epsilon(&values, 1.0), Some(10.0));
}

/// L_data weighs window step t by `step_discount`^(t − 1) (NUNO's code: 0.9), and
/// the particle path's next start is drawn at the model's `sample_noise_scale`.
#[test]
fn l_data_discounts_later_steps_and_draws_its_particle_at_the_models_scale() {
    let dataset = hopper_dataset(400, 1);
    let device = Device::flex();
    let mut model = untrained_hopper_model(&dataset, &device);
    let sampler = nuno::data::WindowSampler::new(&dataset, 2).unwrap();
    let starts: Vec<usize> = (0..16).map(|i| 7 * i).collect();
    let two = window_tensors(&sampler.gather(&starts), 11, false, &device);
    // The same windows cut after their first step.
    let one = nuno::sde::WindowTensors {
        states: two.states.clone().narrow(1, 0, 2),
        actions: two.actions.clone().narrow(1, 0, 1),
    };
    let noise = nuno::nn::normal([16, 2, 11], &mut ChaCha8Rng::seed_from_u64(4), &device);
    let nll = |model: &NeuralSde, windows, noise: Tensor<3>, path, discount| {
        let (nll, _) = model.data_nll(windows, noise, path, discount);
        f64::from(nll.into_scalar::<f32>())
    };
    let data = LikelihoodPath::Data;
    let first = nll(&model, &one, noise.clone().narrow(1, 0, 1), data, 1.0);
    let second = nll(&model, &two, noise.clone(), data, 1.0) - first;
    let discounted = nll(&model, &two, noise.clone(), data, 0.9);
    assert!(
        (discounted - (first + 0.9 * second)).abs() < 1e-4 * (1.0 + discounted.abs()),
        "{discounted} vs {first} + 0.9 × {second}"
    );

    // Scaling the particle's noise by c is the same as drawing c·ε at scale 1.
    let particle = LikelihoodPath::Particle;
    let full = nll(&model, &two, noise.clone() * 0.25, particle, 1.0);
    model.constants.config.sample_noise_scale = 0.25;
    let scaled = nll(&model, &two, noise.clone(), particle, 1.0);
    assert!(
        (scaled - full).abs() < 1e-4 * (1.0 + full.abs()),
        "{scaled} vs {full}"
    );
    let unscaled = {
        model.constants.config.sample_noise_scale = 1.0;
        nll(&model, &two, noise, particle, 1.0)
    };
    assert!(
        (unscaled - full).abs() > 1e-3,
        "the scale reaches the particle path"
    );
}

#[test]
fn threshold_settings_no_table_can_use_are_refused_by_name() {
    let dataset = hopper_dataset(300, 4);
    let device = Device::flex();
    let model = untrained_hopper_model(&dataset, &device);
    let cases = [
        (
            ThresholdConfig::new().with_max_windows(0),
            "max_windows = 0",
        ),
        (ThresholdConfig::new().with_particles(0), "particles = 0"),
        (
            ThresholdConfig::new().with_horizons(vec![5, 0]),
            "horizons [5, 0]",
        ),
        (
            ThresholdConfig::new().with_alphas(vec![0.9, 1.5]),
            "alpha 1.5",
        ),
        (ThresholdConfig::new().with_alphas(vec![0.0]), "alpha 0"),
    ];
    for (config, named) in cases {
        let err = compute_thresholds(&model, &dataset, &config, &device).unwrap_err();
        assert!(err.to_string().contains(named), "{err} should name {named}");
    }
}

#[test]
#[cfg_attr(
    not(feature = "external-tests"),
    ignore = "needs the Python venv (`make venv`); `make test` runs it"
)]
fn artifacts_round_trip_bit_exactly_and_refuse_damage() {
    let dataset = hopper_dataset(3000, 3);
    let (train, valid) = dataset.split_by_trajectory(0.2, 0);
    let device = Device::flex();
    let mut config = small_config(20);
    config.model.reward_model = true;
    let (model, summary) =
        fit(&train, &valid, hopper_spec(), &config, &device, &mut |_| {}).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("hopper");
    let provenance = DynamicsProvenance {
        task: Some(TaskConfig::d4rl(TaskName::Hopper)),
        fit: Some(config.clone()),
        training: Some(summary),
        ..Default::default()
    };
    let saved = save_dynamics(&out, &model, provenance).unwrap();
    let (loaded, metadata) = load_dynamics(&out, &device).unwrap();
    assert_eq!(metadata, saved);
    assert_eq!(
        metadata.provenance.fit.as_ref().unwrap().loss.likelihood,
        LikelihoodPath::Particle
    );
    assert_eq!(collect_tensors(&loaded), collect_tensors(&model));
    assert!(metadata.tensors.contains_key("reward_net.layers.0.weight"));
    assert_eq!(metadata.tensors["g_net.layers.0.weight"], vec![6, 64]);

    // Python's safetensors reads every tensor with the same name, shape and values.
    let report = dir.path().join("report.json");
    common::run_python(
        "safetensors_check.py",
        &[
            out.join("dynamics.safetensors").as_os_str(),
            report.as_os_str(),
        ],
        dir.path(),
    );
    let python: std::collections::BTreeMap<String, (Vec<usize>, f64)> =
        serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    let ours = collect_tensors(&model);
    assert_eq!(python.len(), ours.len());
    for (name, (shape, values)) in &ours {
        let sum: f64 = values.iter().map(|&v| f64::from(v)).sum();
        assert_eq!(&python[name].0, shape, "{name}");
        assert!(
            (python[name].1 - sum).abs() <= 1e-9 * (1.0 + sum.abs()),
            "{name}"
        );
    }

    // Damage: truncated weights, other weights, flipped byte, bad schema, missing file.
    let weights = out.join("dynamics.safetensors");
    let bytes = std::fs::read(&weights).unwrap();
    let expect = |what: &str, check: &dyn Fn(&ArtifactError) -> bool| {
        let err = load_dynamics(&out, &device).unwrap_err();
        assert!(check(&err), "{what}: {err}");
    };
    std::fs::write(&weights, &bytes[..bytes.len() / 2]).unwrap();
    expect("truncated", &|e| {
        matches!(e, ArtifactError::HashMismatch { .. })
    });
    let mut flipped = bytes.clone();
    let last = flipped.len() - 1;
    flipped[last] ^= 0x40;
    std::fs::write(&weights, &flipped).unwrap();
    expect("flipped", &|e| {
        matches!(e, ArtifactError::HashMismatch { .. })
    });
    std::fs::write(&weights, &bytes).unwrap();
    let json_path = out.join("model.json");
    let json = std::fs::read_to_string(&json_path).unwrap();
    std::fs::write(
        &json_path,
        json.replace("\"schema_version\": 2", "\"schema_version\": 99"),
    )
    .unwrap();
    expect("schema", &|e| {
        matches!(e, ArtifactError::Schema { .. }) && e.to_string().contains("schema version 99")
    });
    // A model from before h(η) read η's logit is refused with how to refit, never reinterpreted.
    std::fs::write(
        &json_path,
        json.replace("\"schema_version\": 2", "\"schema_version\": 1"),
    )
    .unwrap();
    expect("version 1", &|e| {
        matches!(e, ArtifactError::Schema { .. })
            && e.to_string().contains("schema version 1")
            && e.to_string().contains("nuno-trainer fit-model")
    });
    // A model.json written before L_data's path was a setting was fitted on eq. 6's
    // particle path, and reads back saying so.
    let mut older: serde_json::Value = serde_json::from_str(&json).unwrap();
    let loss = older.pointer_mut("/fit/loss").unwrap();
    loss.as_object_mut().unwrap().remove("likelihood").unwrap();
    std::fs::write(&json_path, older.to_string()).unwrap();
    let (_, read) = load_dynamics(&out, &device).unwrap();
    assert_eq!(
        read.provenance.fit.unwrap().loss.likelihood,
        LikelihoodPath::Particle
    );
    std::fs::write(&json_path, &json[..json.len() / 2]).unwrap();
    expect("half json", &|e| matches!(e, ArtifactError::Json { .. }));
    std::fs::write(&json_path, &json).unwrap();
    // Weights whose hash matches but whose header is garbage are refused as corrupt.
    let garbage = b"\xff\xff\xff\xff\xff\xff\xff\xffnot a header".to_vec();
    let fake = json.replace(
        &metadata.weights_sha256,
        &nuno::artifact::sha256_hex(&garbage),
    );
    std::fs::write(&json_path, fake).unwrap();
    std::fs::write(&weights, &garbage).unwrap();
    expect("corrupt header", &|e| {
        matches!(e, ArtifactError::Corrupt { .. })
    });
    std::fs::remove_file(&weights).unwrap();
    expect("missing", &|e| {
        matches!(e, ArtifactError::Io { .. }) && e.to_string().contains("dynamics.safetensors")
    });
    assert!(load_dynamics(Path::new("/nonexistent/model"), &device).is_err());
}

/// A damped, driven oscillator with known noise: `dpos = vel dt`,
/// `dvel = (−k·pos − c·vel + b·a) dt + σ dW`.
const OSC: (f32, f32, f32, f32, f32) = (4.0, 0.5, 2.0, 0.3, 0.01); // k, c, b, σ, dt

/// The oscillator's spec: one position, its velocity, dt of OSC.
fn oscillator_spec() -> DynamicsSpec {
    DynamicsSpec {
        obs_dim: 2,
        act_dim: 1,
        split: nuno::envs::StateSplit {
            positions: vec![0],
            velocities: vec![1],
            position_velocity: vec![1],
            angles: Vec::new(),
        },
        dt: f64::from(OSC.4),
    }
}

fn oscillator_dataset(trajectories: usize, steps: usize, seed: u64) -> Dataset {
    use nuno::data::DatasetParts;
    use rand_distr::StandardNormal;
    let (k, c, b, sigma, dt) = OSC;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n = trajectories * steps;
    let (mut obs, mut next, mut act) = (Vec::new(), Vec::new(), Vec::new());
    let mut timeouts = vec![false; n];
    for t in 0..trajectories {
        let mut pos: f32 = rng.random_range(-1.0..1.0);
        let mut vel: f32 = rng.random_range(-1.0..1.0);
        let phase: f32 = rng.random_range(0.0..6.3);
        for i in 0..steps {
            let a = (phase + 0.05 * i as f32).sin() * 0.8 + 0.2 * rng.random_range(-1.0f32..1.0);
            let noise: f32 = rng.sample(StandardNormal);
            let next_pos = pos + vel * dt;
            let next_vel = vel + (-k * pos - c * vel + b * a) * dt + sigma * dt.sqrt() * noise;
            obs.extend([pos, vel]);
            act.push(a);
            next.extend([next_pos, next_vel]);
            (pos, vel) = (next_pos, next_vel);
        }
        timeouts[(t + 1) * steps - 1] = true;
    }
    let parts = DatasetParts {
        observations: ndarray::Array2::from_shape_vec((n, 2), obs).unwrap(),
        actions: ndarray::Array2::from_shape_vec((n, 1), act).unwrap(),
        rewards: ndarray::Array1::zeros(n),
        next_observations: ndarray::Array2::from_shape_vec((n, 2), next).unwrap(),
        terminals: vec![false; n],
        timeouts,
        qpos: None,
        qvel: None,
        action_log_probs: None,
        metadata: Default::default(),
    };
    Dataset::from_parts(parts, Path::new("oscillator")).unwrap()
}

#[test]
fn fitted_drift_and_diffusion_recover_a_known_linear_sde() {
    // Eq. 6's particle path (the default) estimates the drift more closely than
    // one-step likelihoods from the data. RMS drift error for fit seeds 0–3 on the
    // particle path: 5.9 / 10.4 / 7.2 / 6.3 % (fused kernel), 6.0 / 11.8 / 7.4 /
    // 6.7 % (burn); on the data path 26.5 / 14.9 / 20.6 / 13.3 % (fused), 15.3 /
    // 16.7 / 9.3 / 12.4 % (burn): there the best validation NLL falls on an early,
    // noisy step for some seeds, and which one moves with f32 rounding
    // (docs/paper-map.md). The bounds sit above the worst seed. Both recover σ.
    recovers_a_known_linear_sde(LikelihoodPath::Particle, 0.13);
    recovers_a_known_linear_sde(LikelihoodPath::Data, 0.30);
}

fn recovers_a_known_linear_sde(path: LikelihoodPath, drift_tolerance: f64) {
    let (k, c, b, sigma, _) = OSC;
    let dataset = oscillator_dataset(200, 100, 0);
    let (train, valid) = dataset.split_by_trajectory(0.1, 0);
    let spec = oscillator_spec();
    let device = Device::flex();
    // A short run: reach the final learning rate early, then refine.
    let mut config = FitConfig {
        lr_decay_steps: 1000,
        ..small_config(2000)
    };
    config.loss.likelihood = path;
    let (model, _) = fit(&train, &valid, spec, &config, &device, &mut |_| {}).unwrap();

    let rows: Vec<usize> = (0..valid.len()).step_by(3).collect();
    let states: Vec<f32> = rows
        .iter()
        .flat_map(|&i| valid.observations.row(i).to_vec())
        .collect();
    let actions: Vec<f32> = rows.iter().map(|&i| valid.actions[[i, 0]]).collect();
    let n = rows.len();
    let terms = model.terms(
        tensor(states.clone(), [n, 2]),
        tensor(actions.clone(), [n, 1]),
    );
    let drift = to_vec(terms.drift.clone());
    let diffusion = to_vec(terms.diffusion());
    let (mut error2, mut truth2) = (0.0f64, 0.0f64);
    for i in 0..n {
        let (pos, vel, a) = (states[2 * i], states[2 * i + 1], actions[i]);
        let true_acceleration = -k * pos - c * vel + b * a;
        error2 += f64::from(drift[2 * i + 1] - true_acceleration).powi(2);
        truth2 += f64::from(true_acceleration).powi(2);
        // d pos/dt = vel, up to the small penalised residual.
        assert!(
            (drift[2 * i] - vel).abs() < 0.05 * (1.0 + vel.abs()),
            "{path}: position drift {} vs vel {vel}",
            drift[2 * i]
        );
    }
    let relative = (error2 / truth2).sqrt();
    assert!(
        relative < drift_tolerance,
        "{path}: velocity drift off by {:.1}% (RMS)",
        100.0 * relative
    );
    let mean_sigma = (0..n).map(|i| f64::from(diffusion[2 * i + 1])).sum::<f64>() / n as f64;
    let sigma = f64::from(sigma);
    assert!(
        (mean_sigma - sigma).abs() < 0.10 * sigma,
        "{path}: velocity diffusion {mean_sigma} vs {sigma}"
    );
    let mean_position_sigma = (0..n).map(|i| f64::from(diffusion[2 * i])).sum::<f64>() / n as f64;
    assert!(
        mean_position_sigma < 0.1 * sigma,
        "{path}: position diffusion {mean_position_sigma} (noise-free)"
    );
}

#[test]
fn shipped_default_model_loads_with_its_thresholds() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("models/hopper-random");
    let (model, metadata) = load_dynamics(&dir, &Device::flex()).unwrap();
    // Saved before splits named their angles, and before the pose-aware drift:
    // it loads with none, and with the z-score drift it was fitted with.
    let mut saved_spec = hopper_spec();
    saved_spec.split.angles.clear();
    assert_eq!(model.spec(), &saved_spec);
    assert_eq!(model.constants.config.drift_inputs, DriftInputs::ZScores);
    let thresholds = metadata.provenance.thresholds.as_ref().unwrap();
    assert_eq!(thresholds.horizons, vec![5, 10, 15, 20]);
    assert!(
        thresholds
            .get(10, 1.0)
            .is_some_and(|e| e > 0.0 && e <= 10.0)
    );
    assert_eq!(
        metadata.provenance.task,
        Some(TaskConfig::d4rl(TaskName::Hopper))
    );
    assert_eq!(
        metadata.provenance.dataset.as_ref().unwrap().transitions,
        1_000_000
    );
}

#[test]
fn the_shipped_model_is_calibrated_on_fresh_hopper_random_data() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("models/hopper-random");
    let device = Device::flex();
    let (model, metadata) = load_dynamics(&dir, &device).unwrap();
    // fit-model recorded its own report on the held-out trajectories.
    assert!(metadata.provenance.calibration.is_some());
    // Fresh data of the same kind (another random network, another seed).
    let dataset = hopper_dataset(4_000, 5);
    let report = calibration_report(
        &model,
        &dataset,
        metadata.provenance.thresholds.as_ref(),
        0.1,
        &[(-1.0, 1.0); 3],
        &CalibrationConfig::new().with_rows(1500).with_windows(64),
        &device,
    )
    .unwrap();
    let summary = format!("{report:#?}");
    // Not overconfident on real next states (over-dispersed: docs/paper-map.md).
    assert_not_overconfident(&report, &summary);
    assert!(report.h_share_at_median_eta <= 0.25, "{summary}");
    assert!(
        report.diffusion_at(3.0).unwrap().ratio_to_data >= 3.0,
        "{summary}"
    );
    assert_eq!(
        report.horizons.len(),
        4,
        "h = 5, 10, 15, 20 all have windows"
    );
}

#[test]
fn eta_report_on_the_shipped_model_separates_perturbed_data() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("models/hopper-random");
    let device = Device::flex();
    let (model, _) = load_dynamics(&dir, &device).unwrap();
    let dataset = hopper_dataset(4_000, 5);
    let config = EtaReportConfig::new().with_rows(400);
    let report = eta_report(&model, &dataset, 0.1, &config, &device).unwrap();
    assert_eq!(report.rows, 400);
    assert_eq!(report.radius, 0.1);
    assert_eq!(report.perturbed.len(), 2);
    let (near, far) = (&report.perturbed[0], &report.perturbed[1]);
    assert_eq!((near.0, far.0), (1.0, 3.0));
    // η grows with the distance from the data (measured: ~0.95 and ~0.99) ...
    assert!(near.1.auroc_vs_data > 0.85, "{report:?}");
    assert!(far.1.auroc_vs_data > 0.95, "{report:?}");
    assert!(report.data_mean_eta < near.1.mean_eta && near.1.mean_eta < far.1.mean_eta);
    // Random actions against hopper-random's near-uniform ones are a figure of
    // the report (~0.5 today: docs/paper-map.md, known gaps), not a requirement
    // a better η would fail: only that it is a proper AUROC.
    let random = report.random_actions.auroc_vs_data;
    assert!((0.0..=1.0).contains(&random), "{report:?}");

    let none = EtaReportConfig::new().with_rows(0);
    let err = eta_report(&model, &dataset, 0.1, &none, &device).unwrap_err();
    assert!(matches!(err, SdeError::Config(_)) && err.to_string().contains("0 rows"));
    let zero = EtaReportConfig::new().with_radii(vec![1.0, 0.0]);
    let err = eta_report(&model, &dataset, 0.1, &zero, &device).unwrap_err();
    assert!(err.to_string().contains("perturbation scale 0"), "{err}");
    let walker = generate(
        &GenerateConfig::new(TaskConfig::d4rl(TaskName::Walker2d), "random", 200, 0),
        &PortableActor::rlkit_random(17, 6, &[16], 0),
        "walker",
        &|_| {},
    )
    .unwrap();
    let err = eta_report(&model, &walker, 0.1, &config, &device).unwrap_err();
    assert!(err.to_string().contains("17-D observations"), "{err}");
}

/// A fit stopped at its second validation, checkpointed to disk and resumed,
/// ends exactly where the uninterrupted fit ends (records and best weights);
/// a checkpoint of other settings is refused by name.
#[test]
fn a_checkpointed_sde_fit_resumes_where_it_stopped() {
    use nuno::artifact::{latest_checkpoint, load_sde_checkpoint, save_sde_checkpoint};
    use nuno::sde::fit_from;

    let dataset = hopper_dataset(3000, 4);
    let (train, valid) = dataset.split_by_trajectory(0.2, 0);
    let mut config = small_config(40);
    config.model.drift_hidden = vec![16, 16];
    config.model.sigma_hidden = vec![16, 16];
    config.eval_every = 10;
    config.log_every = 5;
    config.valid_windows = 64;
    let device = Device::flex();
    let run = |resume, stop_at: Option<usize>, dir: &Path| {
        let mut records = Vec::new();
        let result = fit_from(
            &train,
            &valid,
            hopper_spec(),
            &config,
            &device,
            resume,
            &mut |r| records.push(r.clone()),
            &mut |state| {
                save_sde_checkpoint(dir, &config, state).unwrap();
                match stop_at {
                    Some(step) if state.step == step => Err(SdeError::Checkpoint("stopped".into())),
                    _ => Ok(()),
                }
            },
        );
        (result, records)
    };
    let scratch = tempfile::tempdir().unwrap();
    let (whole, whole_records) = run(None, None, scratch.path());
    let (whole, _) = whole.unwrap();

    let dir = tempfile::tempdir().unwrap();
    let (stopped, _) = run(None, Some(20), dir.path());
    assert!(stopped.unwrap_err().to_string().contains("stopped"));
    let latest = latest_checkpoint(dir.path()).unwrap().unwrap();
    assert!(latest.ends_with("step-0000020"), "{}", latest.display());
    let state = load_sde_checkpoint(&latest, &config, &device).unwrap();
    assert_eq!(state.records, whole_records[..state.records.len()]);
    let (resumed, later) = run(Some(state), None, dir.path());
    let (resumed, summary) = resumed.unwrap();
    assert_eq!(summary.steps, 40);
    assert_eq!(later, whole_records[whole_records.len() - later.len()..]);
    assert_eq!(
        later[0].step, 25,
        "the resumed fit logs from where it stopped"
    );
    let weights = |m: &NeuralSde| {
        let mut all = Vec::new();
        for (_, (_, values)) in nuno::artifact::collect_tensors(m) {
            all.extend(values);
        }
        all
    };
    assert_eq!(weights(&resumed), weights(&whole));
    assert_eq!(
        resumed.constants.config.h_bias,
        whole.constants.config.h_bias
    );

    // The resumed fit's own checkpoints replaced the one it started from.
    let latest = latest_checkpoint(dir.path()).unwrap().unwrap();
    assert!(latest.ends_with("step-0000040"), "{}", latest.display());
    let mut other = config.clone();
    other.loss.lambda_grad *= 2.0;
    let error = load_sde_checkpoint(&latest, &other, &device).unwrap_err();
    assert!(error.to_string().contains("other settings"), "{error}");
}

/// The fused fit step and burn's autodiff take the same steps (their gradients
/// agree to 1e-5 on one step: `sde::fused_fit`'s unit tests): over 1000 steps on
/// the oscillator their losses stay together, and a fit checkpointed by burn
/// continues on the fused kernel to where burn's own continuation ends. f32
/// rounding is all that differs: at lr 1e-2 early on it grows into per-batch
/// losses up to 15 % apart, which the decayed learning rate pulls back together
/// (measured on an AMD EPYC: final validation NLL −35.8378 fused, −35.8388 burn;
/// mean loss after step 500 −34.554 against −34.550). The bounds, 0.5 % and 1 %,
/// leave room for other CPUs' rounding.
#[test]
fn the_fused_fit_tracks_burns_and_continues_its_checkpoints() {
    use nuno::infer::Kernel;
    use nuno::sde::{SdeFitState, fit_from};

    let dataset = oscillator_dataset(100, 100, 1);
    let (train, valid) = dataset.split_by_trajectory(0.1, 0);
    let spec = oscillator_spec();
    let device = Device::flex();
    let config_for = |kernel| FitConfig {
        lr_decay_steps: 500,
        kernel,
        ..small_config(1000)
    };
    let run = |kernel, resume: Option<SdeFitState>, keep_at: usize| {
        let mut records = Vec::new();
        let mut kept = None;
        let config = config_for(kernel);
        fit_from(
            &train,
            &valid,
            spec.clone(),
            &config,
            &device,
            resume,
            &mut |r| records.push(r.clone()),
            &mut |state| {
                if state.step == keep_at {
                    kept = Some(state.clone());
                }
                Ok(())
            },
        )
        .unwrap();
        (records, kept)
    };
    let (burn, halfway) = run(Kernel::Burn, None, 500);
    let (fused, _) = run(Kernel::Fused, None, 0);
    let (continued, _) = run(Kernel::Fused, halfway, 0);
    let valid_nll =
        |records: &[nuno::sde::FitRecord]| records.iter().rev().find_map(|r| r.valid_nll).unwrap();
    let late_loss = |records: &[nuno::sde::FitRecord]| {
        let late: Vec<f32> = records
            .iter()
            .filter(|r| r.step > 500)
            .map(|r| r.losses.total)
            .collect();
        late.iter().sum::<f32>() / late.len() as f32
    };
    assert_eq!(fused.len(), burn.len());
    for (f, b) in fused.iter().zip(&burn) {
        assert_eq!(f.step, b.step);
    }
    let close = |a: f32, b: f32, tolerance: f32| (a - b).abs() <= tolerance * b.abs();
    let (burn_nll, fused_nll) = (valid_nll(&burn), valid_nll(&fused));
    assert!(
        close(fused_nll, burn_nll, 0.005),
        "final validation NLL: fused {fused_nll}, burn {burn_nll}"
    );
    let (burn_late, fused_late) = (late_loss(&burn), late_loss(&fused));
    assert!(
        close(fused_late, burn_late, 0.01),
        "mean loss after step 500: fused {fused_late}, burn {burn_late}"
    );
    assert_eq!(
        continued.first().unwrap().step,
        550,
        "continues after the checkpoint"
    );
    assert_eq!(continued.last().unwrap().step, 1000);
    let continued_nll = valid_nll(&continued);
    assert!(
        close(continued_nll, burn_nll, 0.005),
        "burn's checkpoint continued fused: {continued_nll}, burn {burn_nll}"
    );
}
