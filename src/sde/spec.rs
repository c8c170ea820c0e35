//! What a dynamics model is fitted to: the state/action widths, the state
//! split, the integration step, and the physical scales measured on the data
//! that keep every network's output near unit size.

use serde::{Deserialize, Serialize};

use super::SdeError;
use crate::data::{Dataset, Normalizer, NormalizerConfig};
use crate::envs::StateSplit;

/// The system being modelled.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DynamicsSpec {
    pub obs_dim: usize,
    pub act_dim: usize,
    /// Positions first, then velocities (eq. 8's `s = [s_pos, s_vel]`).
    pub split: StateSplit,
    /// Integration step: the task's dt between consecutive states (Appendix C.4).
    pub dt: f64,
}

impl DynamicsSpec {
    /// Checks the split covers the state as `[positions..., velocities...]`.
    pub fn validate(&self) -> Result<(), SdeError> {
        let n_pos = self.split.positions.len();
        let contiguous = self.split.positions == (0..n_pos).collect::<Vec<_>>()
            && self.split.velocities == (n_pos..self.obs_dim).collect::<Vec<_>>();
        let paired = self.split.position_velocity.len() == n_pos
            && self
                .split
                .position_velocity
                .iter()
                .all(|v| self.split.velocities.contains(v));
        let mut angles = self.split.angles.clone();
        angles.sort_unstable();
        angles.dedup();
        let angles_ok =
            angles.len() == self.split.angles.len() && angles.iter().all(|&i| i < n_pos);
        if !contiguous || !paired || !angles_ok || self.dt.is_nan() || self.dt <= 0.0 {
            return Err(SdeError::Spec(format!(
                "the state split must list positions 0..{n_pos} then velocities {n_pos}..{}, \
                 pair every position with a velocity, name each angle once among the positions, \
                 and dt must be positive (got {:?}, dt {})",
                self.obs_dim, self.split, self.dt
            )));
        }
        Ok(())
    }

    pub fn n_pos(&self) -> usize {
        self.split.positions.len()
    }

    pub fn n_vel(&self) -> usize {
        self.split.velocities.len()
    }
}

/// Per-dimension scales measured on the training data. Networks see
/// normalised inputs and produce outputs of order one; these scales map the
/// outputs back to physical units, so the drift is integrated in physical
/// units and `d pos/dt = vel` holds exactly.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PhysicalScales {
    /// Normaliser of states, actions, rewards (network inputs).
    pub normalizer: Normalizer,
    /// Std of the finite-difference velocity derivative `(v' − v)/dt`: scales `G·a + H·v`.
    pub acceleration: Vec<f32>,
    /// Std of the state derivative `(s' − s)/dt`: scales the residual drift.
    pub derivative: Vec<f32>,
    /// Std of the one-step change over `sqrt(dt)`: scales the diffusion (per state dimension,
    /// plus the cumulative-reward dimension last when a reward model is fitted).
    pub diffusion: Vec<f32>,
    /// Std of reward over dt: scales the reward drift `f_rew`.
    pub reward_rate: f32,
}

impl PhysicalScales {
    /// Measures the scales on `dataset`.
    pub fn measure(dataset: &Dataset, spec: &DynamicsSpec, config: &NormalizerConfig) -> Self {
        let normalizer = Normalizer::fit(dataset, config);
        let dt = spec.dt as f32;
        let floor = config.std_floor;
        let n = dataset.len().max(1) as f64;
        let std_of = |f: &dyn Fn(usize) -> f32| -> f32 {
            let values: Vec<f64> = (0..dataset.len()).map(|i| f64::from(f(i))).collect();
            let mean = values.iter().sum::<f64>() / n;
            let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
            (var.sqrt() as f32).max(floor)
        };
        let delta =
            |i: usize, d: usize| dataset.next_observations[[i, d]] - dataset.observations[[i, d]];
        let derivative: Vec<f32> = (0..spec.obs_dim)
            .map(|d| std_of(&|i| delta(i, d) / dt))
            .collect();
        let acceleration = spec
            .split
            .velocities
            .iter()
            .map(|&d| derivative[d])
            .collect();
        let mut diffusion: Vec<f32> = (0..spec.obs_dim)
            .map(|d| std_of(&|i| delta(i, d) / dt.sqrt()))
            .collect();
        let reward_std = normalizer.reward.std[0];
        diffusion.push(reward_std / dt.sqrt());
        Self {
            normalizer,
            acceleration,
            derivative,
            diffusion,
            reward_rate: reward_std / dt,
        }
    }
}
