//! Seeded samplers over a dataset: windows of `H` steps inside one trajectory
//! (fitting the SDE, multi-step evaluation), uniform transitions (SAC's real
//! data), and start states (model rollouts).

use rand::Rng;
use rand::seq::SliceRandom;

use super::{DataError, Dataset};
use crate::shared::TransitionBatch;

/// Windows `(s_t, a_t, r_t, ..., s_{t+H})`, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct WindowBatch {
    pub batch: usize,
    pub horizon: usize,
    /// `[batch, horizon + 1, obs_dim]`
    pub states: Vec<f32>,
    /// `[batch, horizon, act_dim]`
    pub actions: Vec<f32>,
    /// `[batch, horizon]`
    pub rewards: Vec<f32>,
}

impl WindowBatch {
    /// Each window's first state, `[batch, obs_dim]`.
    pub fn first_states(&self) -> Vec<f32> {
        let width = self.states.len() / self.batch.max(1);
        let obs_dim = width / (self.horizon + 1);
        self.states
            .chunks_exact(width.max(1))
            .flat_map(|window| &window[..obs_dim])
            .copied()
            .collect()
    }
}

/// Windows of `horizon` transitions that never cross a trajectory boundary.
#[derive(Debug, Clone)]
pub struct WindowSampler<'a> {
    dataset: &'a Dataset,
    horizon: usize,
    starts: Vec<usize>,
}

impl<'a> WindowSampler<'a> {
    /// Every start `t` whose transitions `t..t + horizon` lie in one trajectory.
    pub fn new(dataset: &'a Dataset, horizon: usize) -> Result<Self, DataError> {
        let starts: Vec<usize> = dataset
            .trajectories()
            .iter()
            .filter(|t| horizon > 0 && t.len() >= horizon)
            .flat_map(|t| t.start..=t.end - horizon)
            .collect();
        Self::with_starts(dataset, horizon, starts)
    }

    /// Only the non-overlapping windows: each trajectory cut into consecutive
    /// pieces of `horizon` transitions (a shorter remainder is left out).
    pub fn non_overlapping(dataset: &'a Dataset, horizon: usize) -> Result<Self, DataError> {
        let starts: Vec<usize> = dataset
            .trajectories()
            .iter()
            .filter(|_| horizon > 0)
            .flat_map(|t| {
                (t.start..t.end)
                    .step_by(horizon)
                    .filter(move |s| s + horizon <= t.end)
            })
            .collect();
        Self::with_starts(dataset, horizon, starts)
    }

    fn with_starts(
        dataset: &'a Dataset,
        horizon: usize,
        starts: Vec<usize>,
    ) -> Result<Self, DataError> {
        if starts.is_empty() {
            return Err(DataError::NoWindows { horizon });
        }
        Ok(Self {
            dataset,
            horizon,
            starts,
        })
    }

    /// Number of distinct windows.
    pub fn len(&self) -> usize {
        self.starts.len()
    }

    pub fn is_empty(&self) -> bool {
        self.starts.is_empty()
    }

    /// The first transition of each window.
    pub fn starts(&self) -> &[usize] {
        &self.starts
    }

    /// Up to `max` distinct windows' starts, drawn uniformly without replacement.
    pub fn draw_distinct(&self, max: usize, rng: &mut impl Rng) -> Vec<usize> {
        let mut starts = self.starts.clone();
        starts.shuffle(rng);
        starts.truncate(max);
        starts
    }

    /// `batch` windows drawn uniformly with replacement.
    pub fn sample(&self, batch: usize, rng: &mut impl Rng) -> WindowBatch {
        let picks: Vec<usize> = (0..batch)
            .map(|_| self.starts[rng.random_range(0..self.starts.len())])
            .collect();
        self.gather(&picks)
    }

    /// The windows starting at the given transitions (each from [`starts`](Self::starts)).
    pub fn gather(&self, starts: &[usize]) -> WindowBatch {
        let d = self.dataset;
        let h = self.horizon;
        let mut out = WindowBatch {
            batch: starts.len(),
            horizon: h,
            states: Vec::with_capacity(starts.len() * (h + 1) * d.obs_dim()),
            actions: Vec::with_capacity(starts.len() * h * d.act_dim()),
            rewards: Vec::with_capacity(starts.len() * h),
        };
        for &t in starts {
            out.states.extend(d.observations.row(t).iter());
            for k in t..t + h {
                out.states.extend(d.next_observations.row(k).iter());
                out.actions.extend(d.actions.row(k).iter());
                out.rewards.push(d.rewards[k]);
            }
        }
        out
    }
}

/// Uniform sampling of single transitions.
#[derive(Debug, Clone, Copy)]
pub struct TransitionSampler<'a> {
    dataset: &'a Dataset,
}

impl<'a> TransitionSampler<'a> {
    pub fn new(dataset: &'a Dataset) -> Self {
        Self { dataset }
    }

    /// `batch` transitions drawn uniformly with replacement.
    pub fn sample(&self, batch: usize, rng: &mut impl Rng) -> TransitionBatch {
        let d = self.dataset;
        let mut out = TransitionBatch::with_capacity(batch, d.obs_dim(), d.act_dim());
        for _ in 0..batch {
            let i = rng.random_range(0..d.len());
            out.observations.extend(d.observations.row(i).iter());
            out.actions.extend(d.actions.row(i).iter());
            out.rewards.push(d.rewards[i]);
            out.next_observations
                .extend(d.next_observations.row(i).iter());
            out.terminals.push(if d.terminals[i] { 1.0 } else { 0.0 });
        }
        out
    }
}

/// Start states for model rollouts: dataset states drawn uniformly.
#[derive(Debug, Clone, Copy)]
pub struct StartStateSampler<'a> {
    dataset: &'a Dataset,
}

impl<'a> StartStateSampler<'a> {
    pub fn new(dataset: &'a Dataset) -> Self {
        Self { dataset }
    }

    /// `batch` states, row-major `[batch, obs_dim]`.
    pub fn sample(&self, batch: usize, rng: &mut impl Rng) -> Vec<f32> {
        let d = self.dataset;
        let mut out = Vec::with_capacity(batch * d.obs_dim());
        for _ in 0..batch {
            out.extend(d.observations.row(rng.random_range(0..d.len())).iter());
        }
        out
    }
}
