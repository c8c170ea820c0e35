//! The narrow batch interfaces every concern meets at: a dynamics model
//! stepped on a batch of `(state, action)` rows ([`BatchDynamics`]), a policy
//! acting on a batch of states ([`BatchPolicy`]), and the transitions they
//! produce ([`TransitionBatch`]). The kernels behind them (burn, the fused CPU
//! path) change without touching their callers (rollouts, the evaluator, the
//! server).

use rand::{Rng, RngCore};
use rand_distr::StandardNormal;

/// Everything one Euler–Maruyama step reports, row-major `[batch, ·]`.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelStep {
    /// s' = s + f·dt + Σ·sqrt(dt)·ε: `[batch, state_dim]`
    pub next_states: Vec<f32>,
    /// s + f·dt, the mean of s': `[batch, state_dim]`
    pub means: Vec<f32>,
    /// σ_ϕ(s, a): `[batch, state_dim]`
    pub sigma: Vec<f32>,
    /// h_ϕ(η_ϕ(s, a)): `[batch, state_dim]`
    pub h_eta: Vec<f32>,
    /// η_ϕ(s, a): `[batch]`
    pub eta: Vec<f32>,
    /// What a rollout accumulates against its truncation threshold when that
    /// is not η: `[batch]`. TATU+MOPO penalises MOPO's max ‖σᵢ‖ (η) but
    /// truncates on the ensemble's disagreement; `None` truncates on η.
    pub truncation_signal: Option<Vec<f32>>,
}

impl ModelStep {
    /// Rows `rows` of a step of `[batch, state_dim]` rows, as their own step.
    pub fn rows(&self, rows: std::ops::Range<usize>, state_dim: usize) -> ModelStep {
        let wide = |v: &[f32]| v[rows.start * state_dim..rows.end * state_dim].to_vec();
        ModelStep {
            next_states: wide(&self.next_states),
            means: wide(&self.means),
            sigma: wide(&self.sigma),
            h_eta: wide(&self.h_eta),
            eta: self.eta[rows.clone()].to_vec(),
            truncation_signal: (self.truncation_signal.as_ref()).map(|t| t[rows.clone()].to_vec()),
        }
    }

    /// Row `row`'s truncation signal: [`truncation_signal`](Self::truncation_signal), else η.
    pub fn truncation_at(&self, row: usize) -> f32 {
        self.truncation_signal
            .as_ref()
            .map_or(self.eta[row], |signal| signal[row])
    }
}

/// s' = mean + (σ + h(η))·ε·sqrt(dt) for one state dimension: the EM step's
/// sample, in the order of operations both kernels use (so a sample drawn
/// from a step's reported terms equals the step's own).
#[inline]
pub fn euler_maruyama(mean: f32, sigma: f32, h_eta: f32, noise: f32, sqrt_dt: f32) -> f32 {
    mean + (sigma + h_eta) * noise * sqrt_dt
}

/// The widths and step of a [`BatchDynamics`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BatchShape {
    /// Width of an observation row.
    pub obs_dim: usize,
    /// Width of an action row.
    pub act_dim: usize,
    /// Whether the state carries the cumulative reward r_c after the
    /// observation (NUNO^R), so rewards come from the model.
    pub learns_reward: bool,
    /// The integration step dt of one Euler–Maruyama step.
    pub dt: f64,
}

/// A dynamics model stepped on a batch of `(state, action)` rows at once.
pub trait BatchDynamics: Sync {
    fn shape(&self) -> BatchShape;
    /// One Euler–Maruyama step with the given standard normal noise ε.
    ///
    /// # Shapes
    /// - `states`, `noise`: `[batch, state_dim]`; `actions`: `[batch, act_dim]`
    fn step(&self, states: &[f32], actions: &[f32], noise: &[f32]) -> ModelStep;

    fn obs_dim(&self) -> usize {
        self.shape().obs_dim
    }

    fn act_dim(&self) -> usize {
        self.shape().act_dim
    }

    fn dt(&self) -> f64 {
        self.shape().dt
    }

    /// Width of a state row: `obs_dim`, plus r_c for NUNO^R.
    fn state_dim(&self) -> usize {
        let shape = self.shape();
        shape.obs_dim + usize::from(shape.learns_reward)
    }

    /// Width of a row of ε: one standard normal per state dimension, plus any
    /// the model draws besides its additive noise (an ensemble's member choice).
    /// When it equals `state_dim`, s' = mean + (σ + h(η))·ε·sqrt(dt) exactly, so
    /// callers may run the networks once and add each particle's noise.
    fn noise_dim(&self) -> usize {
        self.state_dim()
    }

    fn learns_reward(&self) -> bool {
        self.shape().learns_reward
    }

    /// The scale of ε at which this model's own rollouts sample unless told
    /// otherwise: 1 samples at the full Σ; a neural SDE fitted with NUNO's code's
    /// convention records sqrt(dt) (`SdeConfig::sample_noise_scale`).
    fn sample_noise_scale(&self) -> f32 {
        1.0
    }

    /// State rows for observation rows (`[batch, obs_dim]`): NUNO^R's cumulative
    /// reward r_c starts at 0, so its increment over a step is that step's reward.
    fn states_from_observations(&self, observations: &[f32]) -> Vec<f32> {
        let obs_dim = self.obs_dim();
        let extra = self.state_dim() - obs_dim;
        if extra == 0 {
            return observations.to_vec();
        }
        observations
            .chunks_exact(obs_dim)
            .flat_map(|o| o.iter().copied().chain(std::iter::repeat_n(0.0, extra)))
            .collect()
    }
}

impl<T: BatchDynamics + ?Sized> BatchDynamics for &T {
    fn shape(&self) -> BatchShape {
        (**self).shape()
    }

    fn step(&self, states: &[f32], actions: &[f32], noise: &[f32]) -> ModelStep {
        (**self).step(states, actions, noise)
    }

    fn noise_dim(&self) -> usize {
        (**self).noise_dim()
    }

    fn sample_noise_scale(&self) -> f32 {
        (**self).sample_noise_scale()
    }
}

/// A policy evaluated on a batch of states at once.
///
/// Implementations must be `Sync`: the evaluator calls one policy from several
/// threads, each with its own random number generator.
pub trait BatchPolicy: Sync {
    /// Width of one state row.
    fn obs_dim(&self) -> usize;
    /// Width of one action row.
    fn act_dim(&self) -> usize;
    /// Actions for `observations`.
    ///
    /// # Shapes
    /// - `observations`: row-major `[batch, obs_dim]`
    /// - returns: row-major `[batch, act_dim]`
    fn act(&self, observations: &[f32], rng: &mut dyn RngCore) -> Vec<f32>;

    /// The actions [`act`](Self::act) gives for the same generator, with each
    /// row's log π(a|s) where the policy has a density (D4RL records it as
    /// `infos/action_log_probs`).
    fn act_logged(&self, observations: &[f32], rng: &mut dyn RngCore) -> LoggedActions {
        LoggedActions {
            actions: self.act(observations, rng),
            log_probs: None,
        }
    }
}

/// Actions and, for a stochastic policy with a density, log π(a|s) per row.
#[derive(Debug, Clone, PartialEq)]
pub struct LoggedActions {
    /// Row-major `[batch, act_dim]`.
    pub actions: Vec<f32>,
    /// `[batch]`
    pub log_probs: Option<Vec<f32>>,
}

/// Transitions `(s, a, r, s', terminal)`, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct TransitionBatch {
    pub observations: Vec<f32>,
    pub actions: Vec<f32>,
    pub rewards: Vec<f32>,
    pub next_observations: Vec<f32>,
    /// 1.0 where the transition ended in a terminal state.
    pub terminals: Vec<f32>,
}

impl TransitionBatch {
    /// An empty batch with room for `rows` transitions.
    pub fn with_capacity(rows: usize, obs_dim: usize, act_dim: usize) -> Self {
        Self {
            observations: Vec::with_capacity(rows * obs_dim),
            actions: Vec::with_capacity(rows * act_dim),
            rewards: Vec::with_capacity(rows),
            next_observations: Vec::with_capacity(rows * obs_dim),
            terminals: Vec::with_capacity(rows),
        }
    }

    /// Number of transitions.
    pub fn len(&self) -> usize {
        self.rewards.len()
    }

    pub fn is_empty(&self) -> bool {
        self.rewards.is_empty()
    }

    /// Appends `other`'s transitions after this batch's.
    pub fn append(&mut self, other: &TransitionBatch) {
        self.observations.extend_from_slice(&other.observations);
        self.actions.extend_from_slice(&other.actions);
        self.rewards.extend_from_slice(&other.rewards);
        self.next_observations
            .extend_from_slice(&other.next_observations);
        self.terminals.extend_from_slice(&other.terminals);
    }
}

/// `n` standard normal draws ε, multiplied by `scale`.
pub fn scaled_noise(n: usize, scale: f32, rng: &mut impl Rng) -> Vec<f32> {
    (0..n)
        .map(|_| rng.sample::<f32, _>(StandardNormal) * scale)
        .collect()
}

/// The shapes [`BatchDynamics::step`] takes, checked the same way by every
/// kernel: `states` and `noise` whole `[batch, state_dim]` rows, `actions` as
/// many `act_dim` rows. Returns the batch. Callers validate what users send
/// (the server answers 422); a mismatch here is a bug in the caller, so it panics.
pub fn step_batch(
    dynamics: &(impl BatchDynamics + ?Sized),
    states: &[f32],
    actions: &[f32],
    noise: &[f32],
) -> usize {
    let (state_dim, act_dim) = (dynamics.state_dim(), dynamics.act_dim());
    let noise_dim = dynamics.noise_dim();
    let batch = states.len() / state_dim.max(1);
    assert!(
        states.len() == batch * state_dim
            && noise.len() == batch * noise_dim
            && actions.len() == batch * act_dim,
        "BatchDynamics::step: {} state, {} action and {} noise values are not \
         [batch, {state_dim}], [batch, {act_dim}] and [batch, {noise_dim}] rows of one batch",
        states.len(),
        actions.len(),
        noise.len()
    );
    batch
}

/// The shape [`BatchPolicy::act`] takes, checked the same way by every kernel:
/// whole `[batch, obs_dim]` rows. Returns the batch; panics otherwise (a bug
/// in the caller, as for [`step_batch`]).
pub fn act_batch(policy: &(impl BatchPolicy + ?Sized), observations: &[f32]) -> usize {
    let obs_dim = policy.obs_dim();
    let batch = observations.len() / obs_dim.max(1);
    assert!(
        observations.len() == batch * obs_dim,
        "BatchPolicy::act: {} observation values are not [batch, {obs_dim}] rows",
        observations.len()
    );
    batch
}
