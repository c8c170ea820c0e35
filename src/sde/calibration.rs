//! Whether the diffusion does its job (eq. 5's intent, Section 4.1–4.3): match
//! the data's noise near the data, rise to W^max beyond it, and make the CVaR
//! truncation fire for rollouts that leave the data while sparing those that
//! follow it. Measured on held-out transitions of the training dataset.
//!
//! - z = (s' − mean)/(Σ·sqrt(dt)) per dimension: std ≈ 1 and 68 % / 95 % inside
//!   ±1 / ±2 when Σ is calibrated;
//! - h(η)'s share of Σ on the data, and Σ on the data against Σ at the data moved
//!   by N(0, (k·r)²) in normalised (s, a), k = 1, 3 and far;
//! - η at real next states against η at model-sampled next states (one step);
//! - accumulated η of open-loop rollouts on dataset actions and on actions uniform
//!   over the task's action space, against h·η_max and the model's thresholds ε(h, α).

use burn::tensor::Device;
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::config::zero_count;
use super::eta_report::{check_dims, mean, uniform_actions};
use super::threshold::{
    ThresholdConfig, ThresholdTable, accumulated_eta_along, window_starts_and_actions,
};
use super::{NeuralSde, SdeError};
use crate::data::{Dataset, WindowSampler};
use crate::nn::standard_normal;
use crate::shared::{BatchDynamics, ModelStep};

/// The band a calibrated z std falls in (the target; Gaussian: 1).
pub const Z_STD_BAND: (f32, f32) = (0.7, 1.4);

/// What [`calibration_report`] samples.
#[derive(burn::config::Config, Debug, PartialEq)]
pub struct CalibrationConfig {
    /// Held-out transitions drawn (uniformly, with replacement).
    #[config(default = 2000)]
    pub rows: usize,
    /// Perturbation scales, in multiples of the radius r of L_sc.
    #[config(default = "vec![1.0, 3.0]")]
    pub radii: Vec<f32>,
    /// "Far" points: the data moved by N(0, (k·r)²) with this k (30·0.1 = three
    /// standard deviations of every normalised input).
    #[config(default = 30.0)]
    pub far_radii: f32,
    /// Open-loop windows per horizon, drawn without replacement.
    #[config(default = 512)]
    pub windows: usize,
    /// Particle trajectories per window (as the thresholds use).
    #[config(default = 5)]
    pub particles: usize,
    #[config(default = 0)]
    pub seed: u64,
}

impl CalibrationConfig {
    /// Refuses settings no report can be made from, naming the field.
    pub fn validate(&self) -> Result<(), SdeError> {
        let bad = |message: String| SdeError::Config(format!("calibration: {message}"));
        if let Some(message) = zero_count(&[
            ("rows", self.rows),
            ("windows", self.windows),
            ("particles", self.particles),
        ]) {
            return Err(bad(message));
        }
        let scales = self.radii.iter().chain(std::iter::once(&self.far_radii));
        if let Some(k) = scales.into_iter().find(|k| !(k.is_finite() && **k > 0.0)) {
            return Err(bad(format!("perturbation scale {k} must be > 0")));
        }
        Ok(())
    }
}

/// One state dimension's standardised residuals and h(η)'s share of its Σ.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DimensionCalibration {
    pub z_mean: f32,
    pub z_std: f32,
    /// Fraction of |z| ≤ 1 (Gaussian: 0.683).
    pub within_one: f32,
    /// Fraction of |z| ≤ 2 (Gaussian: 0.954).
    pub within_two: f32,
    /// Mean of h(η)/Σ on the held-out data.
    pub h_share: f32,
}

/// Mean Σ (in units of each dimension's diffusion scale) at a set of points.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DiffusionAt {
    /// Perturbation scale k (0 = the data itself).
    pub radii: f32,
    pub mean_eta: f32,
    pub mean_sigma: f32,
    /// mean Σ here / mean Σ on the data.
    pub ratio_to_data: f32,
}

/// How often rollouts pass ε(h, α), on dataset actions and on random actions.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TruncationRate {
    pub alpha: f64,
    pub epsilon: f32,
    pub dataset_actions: f32,
    pub random_actions: f32,
}

/// Open-loop rollouts of one horizon h from held-out windows.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HorizonCalibration {
    pub horizon: usize,
    pub windows: usize,
    pub dataset_mean_accumulated_eta: f32,
    pub random_mean_accumulated_eta: f32,
    /// h·η_max, the most η can accumulate.
    pub bound: f32,
    pub truncation: Vec<TruncationRate>,
}

/// The calibration of a fitted model on held-out data.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CalibrationReport {
    pub rows: usize,
    /// Per integrated state dimension (r_c last for NUNO^R).
    pub dimensions: Vec<DimensionCalibration>,
    /// Share of dimensions whose z std lies in [`Z_STD_BAND`].
    pub z_std_in_band: f32,
    pub median_eta: f32,
    /// h(η)'s share of Σ (mean over dimensions) at the rows around the median η
    /// (the 45th–55th percentile).
    pub h_share_at_median_eta: f32,
    /// The data (k = 0), the data moved by k·r for each configured k, and far.
    pub diffusion: Vec<DiffusionAt>,
    /// Mean η at real next states, with the dataset's next action.
    pub eta_next_real: f32,
    /// Mean η at model-sampled next states (at the model's `sample_noise_scale`), with the same action.
    pub eta_next_model: f32,
    /// One entry per horizon of the threshold table with held-out windows of that length.
    pub horizons: Vec<HorizonCalibration>,
}

impl CalibrationReport {
    /// The diffusion entry for perturbation scale `k` (0: the data).
    pub fn diffusion_at(&self, k: f32) -> Option<&DiffusionAt> {
        self.diffusion.iter().find(|d| d.radii == k)
    }

    /// The truncation rates at `(horizon, alpha)`.
    pub fn truncation(&self, horizon: usize, alpha: f64) -> Option<&TruncationRate> {
        self.horizons
            .iter()
            .find(|h| h.horizon == horizon)?
            .truncation
            .iter()
            .find(|t| (t.alpha - alpha).abs() < 1e-9)
    }
}

/// The model's step at a batch of points without noise: means, σ, h(η) and η.
fn terms_at(model: &NeuralSde, states: &[f32], actions: &[f32]) -> ModelStep {
    BatchDynamics::step(model, states, actions, &vec![0.0; states.len()])
}

/// Calibration of `model` on `held_out` (transitions the fit did not train on),
/// with the truncation rates at the model's `thresholds`; `radius` is r of L_sc,
/// `action_space` each action dimension's `(low, high)` in the task.
pub fn calibration_report(
    model: &NeuralSde,
    held_out: &Dataset,
    thresholds: Option<&ThresholdTable>,
    radius: f32,
    action_space: &[(f32, f32)],
    config: &CalibrationConfig,
    device: &Device,
) -> Result<CalibrationReport, SdeError> {
    check_inputs(model, held_out, radius, action_space, config)?;
    let state_dim = model.constants.state_dim();
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    let batch = HeldOutBatch::draw(model, held_out, config.rows, &mut rng)?;
    let data = terms_at(model, &batch.states, &batch.actions);
    let dimensions = dimension_calibrations(model, &batch, &data);
    let in_band = dimensions
        .iter()
        .filter(|d| d.z_std >= Z_STD_BAND.0 && d.z_std <= Z_STD_BAND.1)
        .count();
    let (median_eta, h_share_at_median_eta) = h_share_around_median_eta(&data, state_dim);
    let diffusion = diffusion_profile(model, &batch, &data, radius, config, &mut rng);
    let (eta_next_real, eta_next_model) = eta_one_step_ahead(model, &batch, &mut rng);
    let horizons = thresholds.map_or_else(Vec::new, |table| {
        open_loop_calibration(
            model,
            held_out,
            table,
            action_space,
            config,
            &mut rng,
            device,
        )
    });
    Ok(CalibrationReport {
        rows: batch.rows,
        z_std_in_band: in_band as f32 / state_dim as f32,
        dimensions,
        median_eta,
        h_share_at_median_eta,
        diffusion,
        eta_next_real,
        eta_next_model,
        horizons,
    })
}

/// Refuses a report that cannot be made, naming what is wrong.
fn check_inputs(
    model: &NeuralSde,
    held_out: &Dataset,
    radius: f32,
    action_space: &[(f32, f32)],
    config: &CalibrationConfig,
) -> Result<(), SdeError> {
    check_dims(model, held_out)?;
    config.validate()?;
    if !(radius.is_finite() && radius > 0.0) {
        return Err(SdeError::Config(format!(
            "calibration: radius {radius} must be > 0"
        )));
    }
    let act_dim = model.constants.spec.act_dim;
    if action_space.len() != act_dim
        || !action_space
            .iter()
            .all(|(low, high)| low.is_finite() && high.is_finite() && low <= high)
    {
        return Err(SdeError::Config(format!(
            "calibration: action space {action_space:?} is not {act_dim} (low, high) pairs"
        )));
    }
    Ok(())
}

/// Held-out rows drawn for the one-step measures, laid out as the model's batches.
struct HeldOutBatch {
    rows: usize,
    /// Integrated states (with r_c = 0 appended for NUNO^R).
    states: Vec<f32>,
    /// The real next states (r_c: the step's reward).
    targets: Vec<f32>,
    actions: Vec<f32>,
    /// The action the dataset takes at the next state (for η one step ahead).
    next_actions: Vec<f32>,
}

impl HeldOutBatch {
    /// `rows` transitions drawn uniformly, with replacement, among those with a next
    /// action in the same trajectory.
    fn draw(
        model: &NeuralSde,
        held_out: &Dataset,
        rows: usize,
        rng: &mut ChaCha8Rng,
    ) -> Result<Self, SdeError> {
        let continued: Vec<usize> = held_out
            .trajectories()
            .iter()
            .flat_map(|t| t.start..t.end - 1)
            .collect();
        if continued.is_empty() {
            return Err(SdeError::Config(
                "calibration: the held-out data has no trajectory of two or more steps".into(),
            ));
        }
        let c = &model.constants;
        let (act_dim, state_dim) = (c.spec.act_dim, c.state_dim());
        let mut batch = HeldOutBatch {
            rows,
            states: Vec::with_capacity(rows * state_dim),
            targets: Vec::with_capacity(rows * state_dim),
            actions: Vec::with_capacity(rows * act_dim),
            next_actions: Vec::with_capacity(rows * act_dim),
        };
        for _ in 0..rows {
            let i = continued[rng.random_range(0..continued.len())];
            batch.states.extend(held_out.observations.row(i).iter());
            batch
                .targets
                .extend(held_out.next_observations.row(i).iter());
            if c.config.reward_model {
                // r_c starts at 0 and gains the step's reward.
                batch.states.push(0.0);
                batch.targets.push(held_out.rewards[i]);
            }
            batch.actions.extend(held_out.actions.row(i).iter());
            batch
                .next_actions
                .extend(held_out.actions.row(i + 1).iter());
        }
        Ok(batch)
    }
}

/// z per integrated dimension, and h(η)'s share of Σ, from the model's `data` terms.
fn dimension_calibrations(
    model: &NeuralSde,
    batch: &HeldOutBatch,
    data: &ModelStep,
) -> Vec<DimensionCalibration> {
    let c = &model.constants;
    let (n, state_dim) = (batch.rows, c.state_dim());
    let sqrt_dt = c.spec.dt.sqrt() as f32;
    (0..state_dim)
        .map(|d| {
            let column =
                |v: &[f32]| -> Vec<f32> { v.iter().skip(d).step_by(state_dim).copied().collect() };
            let (target, mu) = (column(&batch.targets), column(&data.means));
            let (sigma, h) = (column(&data.sigma), column(&data.h_eta));
            let z: Vec<f32> = (0..n)
                .map(|r| (target[r] - mu[r]) / ((sigma[r] + h[r]) * sqrt_dt))
                .collect();
            let z_mean = mean(&z);
            let z_var = z.iter().map(|v| (v - z_mean).powi(2)).sum::<f32>() / n as f32;
            let share =
                |bound: f32| z.iter().filter(|v| v.abs() <= bound).count() as f32 / n as f32;
            let h_share: Vec<f32> = (0..n).map(|r| h[r] / (sigma[r] + h[r])).collect();
            DimensionCalibration {
                z_mean,
                z_std: z_var.sqrt(),
                within_one: share(1.0),
                within_two: share(2.0),
                h_share: mean(&h_share),
            }
        })
        .collect()
}

/// The median η on the data, and h(η)'s share of Σ at the rows around it (the 45th–55th
/// percentile).
fn h_share_around_median_eta(data: &ModelStep, state_dim: usize) -> (f32, f32) {
    let n = data.eta.len();
    let row_share = |r: usize| -> f32 {
        let span = r * state_dim..(r + 1) * state_dim;
        let shares: Vec<f32> = data.h_eta[span.clone()]
            .iter()
            .zip(&data.sigma[span])
            .map(|(h, s)| h / (s + h))
            .collect();
        mean(&shares)
    };
    let mut by_eta: Vec<usize> = (0..n).collect();
    by_eta.sort_by(|&a, &b| data.eta[a].total_cmp(&data.eta[b]));
    let middle = &by_eta[(n * 45 / 100).min(n - 1)..(n * 55 / 100 + 1).min(n)];
    let shares: Vec<f32> = middle.iter().map(|&r| row_share(r)).collect();
    (data.eta[by_eta[n / 2]], mean(&shares))
}

/// Mean Σ (each dimension in units of its diffusion scale) on the data, then at the data
/// moved by N(0, (k·r)²) in normalised (s, a) for each configured k and far.
fn diffusion_profile(
    model: &NeuralSde,
    batch: &HeldOutBatch,
    data: &ModelStep,
    radius: f32,
    config: &CalibrationConfig,
    rng: &mut ChaCha8Rng,
) -> Vec<DiffusionAt> {
    let c = &model.constants;
    let (obs_dim, act_dim, state_dim) = (c.spec.obs_dim, c.spec.act_dim, c.state_dim());
    let scale = &c.scales.diffusion[..state_dim];
    let mean_sigma = |t: &ModelStep| -> f32 {
        let relative: Vec<f32> = t
            .sigma
            .iter()
            .zip(&t.h_eta)
            .enumerate()
            .map(|(i, (s, h))| (s + h) / scale[i % state_dim])
            .collect();
        mean(&relative)
    };
    let data_sigma = mean_sigma(data);
    let normalizer = &c.scales.normalizer;
    let mut diffusion = vec![DiffusionAt {
        radii: 0.0,
        mean_eta: mean(&data.eta),
        mean_sigma: data_sigma,
        ratio_to_data: 1.0,
    }];
    for &k in config
        .radii
        .iter()
        .chain(std::iter::once(&config.far_radii))
    {
        // Moved in normalised (s, a), mapped back to physical units.
        let shift = k * radius;
        let mut moved_states = batch.states.clone();
        let mut moved_actions = batch.actions.clone();
        for row in moved_states.chunks_exact_mut(state_dim) {
            let noise = standard_normal(obs_dim, rng);
            for (d, e) in noise.iter().enumerate() {
                row[d] += e * shift * normalizer.state.std[d];
            }
        }
        for row in moved_actions.chunks_exact_mut(act_dim) {
            let noise = standard_normal(act_dim, rng);
            for (d, e) in noise.iter().enumerate() {
                row[d] += e * shift * normalizer.action.std[d];
            }
        }
        let moved = terms_at(model, &moved_states, &moved_actions);
        let sigma = mean_sigma(&moved);
        diffusion.push(DiffusionAt {
            radii: k,
            mean_eta: mean(&moved.eta),
            mean_sigma: sigma,
            ratio_to_data: sigma / data_sigma,
        });
    }
    diffusion
}

/// Mean η one step ahead, with the dataset's next action: at the real next states, and at
/// model samples drawn at the scale the model's rollouts sample at.
fn eta_one_step_ahead(model: &NeuralSde, batch: &HeldOutBatch, rng: &mut ChaCha8Rng) -> (f32, f32) {
    let scale = model.sample_noise_scale();
    let noise: Vec<f32> = standard_normal(batch.states.len(), rng)
        .into_iter()
        .map(|e| e * scale)
        .collect();
    let sampled = BatchDynamics::step(model, &batch.states, &batch.actions, &noise).next_states;
    let real = mean(&terms_at(model, &batch.targets, &batch.next_actions).eta);
    let modelled = mean(&terms_at(model, &sampled, &batch.next_actions).eta);
    (real, modelled)
}

/// Open-loop accumulated η and truncation rates, per horizon of `table` that
/// has held-out windows of its length.
fn open_loop_calibration(
    model: &NeuralSde,
    held_out: &Dataset,
    table: &ThresholdTable,
    action_space: &[(f32, f32)],
    config: &CalibrationConfig,
    rng: &mut ChaCha8Rng,
    device: &Device,
) -> Vec<HorizonCalibration> {
    let rollout_config = ThresholdConfig {
        particles: config.particles,
        ..ThresholdConfig::new()
    };
    let mut horizons = Vec::new();
    for (&h, epsilons) in table.horizons.iter().zip(&table.values) {
        let Ok(sampler) = WindowSampler::non_overlapping(held_out, h) else {
            continue;
        };
        let mut starts = sampler.starts().to_vec();
        starts.shuffle(rng);
        starts.truncate(config.windows);
        let (initial, dataset_actions) = window_starts_and_actions(model, held_out, &starts, h);
        let random_actions = uniform_actions(action_space, starts.len() * h, rng);
        let mut along = |actions: &[f32]| {
            accumulated_eta_along(model, &initial, actions, h, &rollout_config, rng, device)
        };
        let (on_data, on_random) = (along(&dataset_actions), along(&random_actions));
        let rate = |totals: &[f32], epsilon: f32| {
            totals.iter().filter(|&&t| t > epsilon).count() as f32 / totals.len() as f32
        };
        let truncation = table
            .alphas
            .iter()
            .zip(epsilons)
            .filter_map(|(&alpha, epsilon)| {
                epsilon.map(|epsilon| TruncationRate {
                    alpha,
                    epsilon,
                    dataset_actions: rate(&on_data, epsilon),
                    random_actions: rate(&on_random, epsilon),
                })
            })
            .collect();
        horizons.push(HorizonCalibration {
            horizon: h,
            windows: starts.len(),
            dataset_mean_accumulated_eta: mean(&on_data),
            random_mean_accumulated_eta: mean(&on_random),
            bound: h as f32 * model.constants.config.eta_max,
            truncation,
        });
    }
    horizons
}
