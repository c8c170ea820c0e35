//! Open-loop prediction error by horizon: the model's drift-only rollouts along
//! held-out action sequences against the truth, next to the constant-velocity
//! predictor (`pos' = pos + vel·dt`, `vel' = vel`) as the baseline a learned
//! model must beat.

use burn::tensor::Device;
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::model::NeuralSde;
use super::rollout::OpenLoop;
use crate::data::{Dataset, WindowSampler};

/// RMSE after `horizon` open-loop steps, in normalised state units.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct HorizonError {
    pub horizon: usize,
    pub windows: usize,
    pub model_rmse: f64,
    pub constant_velocity_rmse: f64,
}

/// Prediction error of `model` on `dataset` for horizons `1..=max_horizon`
/// (those with at least one window), over at most `max_windows` windows each.
pub fn prediction_error(
    model: &NeuralSde,
    dataset: &Dataset,
    max_horizon: usize,
    max_windows: usize,
    seed: u64,
    device: &Device,
) -> Vec<HorizonError> {
    let spec = model.spec().clone();
    let std = &model.constants.scales.normalizer.state.std;
    let reward_model = model.constants.config.reward_model;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut out = Vec::new();
    for horizon in 1..=max_horizon {
        let Ok(sampler) = WindowSampler::new(dataset, horizon) else {
            break;
        };
        let mut starts = sampler.starts().to_vec();
        starts.shuffle(&mut rng);
        starts.truncate(max_windows);
        let windows = sampler.gather(&starts);
        let obs = spec.obs_dim;
        let mut initial = Vec::with_capacity(starts.len() * (obs + 1));
        for w in 0..starts.len() {
            let row = w * (horizon + 1) * obs;
            initial.extend_from_slice(&windows.states[row..row + obs]);
            if reward_model {
                initial.push(0.0);
            }
        }
        let plan = OpenLoop {
            horizon,
            particles: 1,
            noise_scale: 0.0,
        };
        let rollout = model.rollout_open_loop(&initial, &windows.actions, plan, &mut rng, device);
        let (mut model_se, mut baseline_se) = (0.0f64, 0.0f64);
        for w in 0..starts.len() {
            let base = w * (horizon + 1) * obs;
            let first = &windows.states[base..base + obs];
            let truth = &windows.states[base + horizon * obs..base + (horizon + 1) * obs];
            let predicted = rollout.state(w, 0, horizon);
            let mut baseline = first.to_vec();
            for (&p, &v) in spec
                .split
                .positions
                .iter()
                .zip(&spec.split.position_velocity)
            {
                baseline[p] += horizon as f32 * first[v] * spec.dt as f32;
            }
            for d in 0..obs {
                model_se += f64::from((predicted[d] - truth[d]) / std[d]).powi(2);
                baseline_se += f64::from((baseline[d] - truth[d]) / std[d]).powi(2);
            }
        }
        let n = (starts.len() * obs) as f64;
        out.push(HorizonError {
            horizon,
            windows: starts.len(),
            model_rmse: (model_se / n).sqrt(),
            constant_velocity_rmse: (baseline_se / n).sqrt(),
        });
    }
    out
}
