//! What the drift networks G, H and f_res of eq. 8 see of the state: the
//! paper's z-scores, or NUNO's code's pose features (`RBD_Drift`, D4 of the
//! faithful-NUNO issue), where an angle enters through cos θ − cos m and
//! sin θ − sin m (m its mean on the data), so the networks see the pose as the
//! rigid-body terms depend on it, and the actuator net G sees the pose too.
//!
//! ```text
//! φ(s) = [ẑ(positions that are not angles), cos θ − cos m, sin θ − sin m, ẑ(velocities)]
//! G(φ_vel)·a (z-scores) or G(φ)·a (pose),  H(φ)·v̂,  f_res(φ, â)
//! ```
//!
//! Under z-scores φ is the normalised observation itself, so the drift is eq. 8
//! as the paper writes it. σ_ϕ and η_ϕ see the normalised `(s, a)` in both forms,
//! as NUNO's code's diffusion does.

use std::ops::Range;

use burn::tensor::{Int, Tensor, TensorData};

use super::model::{SdeConstants, constant};

/// The drift networks' inputs (`SdeConfig::drift_inputs`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DriftInputs {
    /// Eq. 8 as written: G sees the velocities, H the state, f_res the state
    /// and action, each as z-scores.
    ZScores,
    /// NUNO's code's `RBD_Drift` inputs: angles as cos and sin about their mean,
    /// the other positions and the velocities as z-scores; G, H and f_res all
    /// see the pose.
    Pose,
}

crate::shared::named_enum!(DriftInputs, "drift inputs", DriftInputs::ZScores => "z-scores", DriftInputs::Pose => "pose");

/// φ(s) of one model: which observation enters how, and where G reads.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct DriftFeatures {
    /// Observation indices entering as z-scores, in φ's order: the positions
    /// that are not angles, then (after the angle features) the velocities.
    pub(crate) positions: Vec<usize>,
    pub(crate) velocities: Vec<usize>,
    /// Observation indices entering as cos and sin, and cos m, sin m of each.
    pub(crate) angles: Vec<usize>,
    pub(crate) cos_mean: Vec<f32>,
    pub(crate) sin_mean: Vec<f32>,
    pub(crate) mean: Vec<f32>,
    pub(crate) std: Vec<f32>,
    /// The columns of φ that G reads.
    pub(crate) g_columns: Range<usize>,
}

impl DriftFeatures {
    pub fn of(constants: &SdeConstants) -> Self {
        let split = &constants.spec.split;
        let state = &constants.scales.normalizer.state;
        let obs = constants.spec.obs_dim;
        let pose = constants.config.drift_inputs == DriftInputs::Pose;
        let angles: Vec<usize> = if pose {
            split.angles.clone()
        } else {
            Vec::new()
        };
        let positions: Vec<usize> = split
            .positions
            .iter()
            .copied()
            .filter(|i| !angles.contains(i))
            .collect();
        let width = obs + angles.len();
        let n_vel = split.velocities.len();
        Self {
            cos_mean: angles.iter().map(|&i| state.mean[i].cos()).collect(),
            sin_mean: angles.iter().map(|&i| state.mean[i].sin()).collect(),
            positions,
            velocities: split.velocities.clone(),
            angles,
            mean: state.mean[..obs].to_vec(),
            std: state.std[..obs].to_vec(),
            g_columns: if pose { 0..width } else { width - n_vel..width },
        }
    }

    /// Width of φ.
    pub fn width(&self) -> usize {
        self.positions.len() + 2 * self.angles.len() + self.velocities.len()
    }

    /// The columns of φ G reads.
    pub fn g_columns(&self) -> Range<usize> {
        self.g_columns.clone()
    }

    /// Appends φ of one observation to `out`.
    pub fn extend(&self, obs: &[f32], out: &mut Vec<f32>) {
        let z = |i: &usize| (obs[*i] - self.mean[*i]) / self.std[*i];
        out.extend(self.positions.iter().map(z));
        let angles = self.angles.iter().map(|&i| obs[i]);
        out.extend(angles.clone().zip(&self.cos_mean).map(|(t, m)| t.cos() - m));
        out.extend(angles.zip(&self.sin_mean).map(|(t, m)| t.sin() - m));
        out.extend(self.velocities.iter().map(z));
    }

    /// Adds (∂φ/∂obs)ᵀ·`grad` (`grad` = ∂L/∂φ of one row) to `obs_grad`.
    pub fn add_gradient(&self, obs: &[f32], grad: &[f32], obs_grad: &mut [f32]) {
        let (n_z, n_a) = (self.positions.len(), self.angles.len());
        for (&i, g) in self.positions.iter().zip(grad) {
            obs_grad[i] += g / self.std[i];
        }
        for (k, &i) in self.angles.iter().enumerate() {
            let (sin, cos) = obs[i].sin_cos();
            obs_grad[i] += -sin * grad[n_z + k] + cos * grad[n_z + n_a + k];
        }
        for (&i, g) in self.velocities.iter().zip(&grad[n_z + 2 * n_a..]) {
            obs_grad[i] += g / self.std[i];
        }
    }

    /// φ of a batch of observations, `[batch, obs]` → `[batch, width]` (burn).
    pub fn tensor(&self, obs: Tensor<2>) -> Tensor<2> {
        let device = obs.device();
        let columns = |indices: &[usize]| {
            let indices: Vec<i64> = indices.iter().map(|&i| i as i64).collect();
            let n = indices.len();
            obs.clone().select(
                1,
                Tensor::<1, Int>::from_data(TensorData::new(indices, [n]), &device),
            )
        };
        let z = |indices: &[usize]| {
            let pick =
                |values: &[f32]| -> Vec<f32> { indices.iter().map(|&i| values[i]).collect() };
            (columns(indices) - constant(&pick(&self.mean), &device).unsqueeze())
                / constant(&pick(&self.std), &device).unsqueeze()
        };
        let mut parts = Vec::new();
        if !self.positions.is_empty() {
            parts.push(z(&self.positions));
        }
        if !self.angles.is_empty() {
            let theta = columns(&self.angles);
            parts.push(theta.clone().cos() - constant(&self.cos_mean, &device).unsqueeze());
            parts.push(theta.sin() - constant(&self.sin_mean, &device).unsqueeze());
        }
        parts.push(z(&self.velocities));
        Tensor::cat(parts, 1)
    }
}

#[cfg(test)]
mod tests {
    use burn::tensor::Device;

    use super::*;
    use crate::data::{Normalizer, Stats};
    use crate::envs::StateSplit;
    use crate::nn::to_f32_vec;
    use crate::sde::{DynamicsSpec, PhysicalScales, SdeConfig};

    /// A height z and a pitch θ with their velocities: obs = [z, θ, ż, θ̇].
    fn constants(drift_inputs: DriftInputs) -> SdeConstants {
        let stats = |mean: Vec<f32>, std: Vec<f32>| Stats { mean, std };
        let mut config = SdeConfig::new();
        config.drift_inputs = drift_inputs;
        SdeConstants {
            spec: DynamicsSpec {
                obs_dim: 4,
                act_dim: 1,
                split: StateSplit {
                    positions: vec![0, 1],
                    velocities: vec![2, 3],
                    position_velocity: vec![2, 3],
                    angles: vec![1],
                },
                dt: 0.01,
            },
            scales: PhysicalScales {
                normalizer: Normalizer {
                    state: stats(vec![1.0, 0.2, 0.0, 0.5], vec![0.5, 0.3, 2.0, 4.0]),
                    action: stats(vec![0.0], vec![1.0]),
                    reward: stats(vec![0.0], vec![1.0]),
                },
                acceleration: vec![1.0; 2],
                derivative: vec![1.0; 4],
                diffusion: vec![1.0; 5],
                reward_rate: 1.0,
            },
            config,
        }
    }

    const OBS: [f32; 4] = [1.5, 0.7, 1.0, -1.5];

    fn assert_near(what: &str, got: &[f32], want: &[f32]) {
        assert_eq!(got.len(), want.len(), "{what}: {got:?} against {want:?}");
        for (g, w) in got.iter().zip(want) {
            assert!((g - w).abs() < 1e-6, "{what}: {got:?} against {want:?}");
        }
    }

    #[test]
    fn pose_features_are_cos_and_sin_about_the_mean_by_hand() {
        let features = DriftFeatures::of(&constants(DriftInputs::Pose));
        let want = [
            1.0,
            0.7f32.cos() - 0.2f32.cos(),
            0.7f32.sin() - 0.2f32.sin(),
            0.5,
            -0.5,
        ];
        let mut phi = Vec::new();
        features.extend(&OBS, &mut phi);
        assert_near("host φ", &phi, &want);
        let obs = Tensor::<2>::from_data(TensorData::new(OBS.to_vec(), [1, 4]), &Device::flex());
        assert_near("burn φ", &to_f32_vec(features.tensor(obs)), &want);
        assert_eq!(features.g_columns(), 0..5, "the actuator net sees the pose");

        let grad = [1.0, 2.0, 3.0, 4.0, 5.0];
        let mut obs_grad = [0.0; 4];
        features.add_gradient(&OBS, &grad, &mut obs_grad);
        let angle = -0.7f32.sin() * 2.0 + 0.7f32.cos() * 3.0;
        assert_near(
            "∂φ/∂obs",
            &obs_grad,
            &[1.0 / 0.5, angle, 4.0 / 2.0, 5.0 / 4.0],
        );
    }

    #[test]
    fn z_score_features_are_the_normalised_observation() {
        let features = DriftFeatures::of(&constants(DriftInputs::ZScores));
        let mut phi = Vec::new();
        features.extend(&OBS, &mut phi);
        assert_near("φ", &phi, &[1.0, 0.5 / 0.3, 0.5, -0.5]);
        assert_eq!(features.g_columns(), 2..4, "G sees the velocities (eq. 8)");
    }
}
