//! One model step for a batch of observations with `particles` samples each:
//! the SDE's terms, the sampled next observations, and what the task's rules
//! (or NUNO^R's learned reward) make of them. What the server's `step` answers.

use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::envs::Rules;
use crate::shared::{BatchDynamics, ModelStep, euler_maruyama, scaled_noise};

/// A batch step's results, row-major; `b` items, `p` particles, `d` = obs_dim.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ParticleStep {
    pub batch: usize,
    pub particles: usize,
    pub obs_dim: usize,
    /// s + f(s, a)·dt: `[b, d]`
    pub mean: Vec<f32>,
    /// σ_ϕ(s, a): `[b, d]`
    pub sigma: Vec<f32>,
    /// h_ϕ(η_ϕ(s, a)): `[b, d]`
    pub h_eta: Vec<f32>,
    /// η_ϕ(s, a): `[b]`
    pub eta: Vec<f32>,
    /// Sampled next observations: `[b, p, d]`
    pub next_states: Vec<f32>,
    /// r(s, a, s'): the task's reward, or the learned r_c increment for NUNO^R: `[b, p]`
    pub rewards: Vec<f32>,
    /// r − λ_pen·η: `[b, p]`
    pub penalized_rewards: Vec<f32>,
    /// The task's termination rule on s': `[b, p]`
    pub terminals: Vec<bool>,
}

/// NUNO's penalised reward r − λ_pen·η(s, a) (Section 4.3).
pub fn penalized_reward(reward: f32, penalty: f64, eta: f32) -> f32 {
    reward - (penalty * f64::from(eta)) as f32
}

/// How a batch step samples and penalises.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ParticleConfig {
    /// Samples per item.
    pub particles: usize,
    /// λ_pen of the penalised reward.
    pub penalty: f64,
    /// Multiplies ε: 1 samples the SDE, 0 follows the drift.
    pub noise_scale: f32,
}

/// Steps `observations` (`[b, obs_dim]`) under `actions` (`[b, act_dim]`).
pub fn step_particles(
    dynamics: &dyn BatchDynamics,
    rules: &Rules,
    observations: &[f32],
    actions: &[f32],
    config: ParticleConfig,
    rng: &mut ChaCha8Rng,
) -> ParticleStep {
    let terms = particle_terms(dynamics, observations, actions);
    sample_particles(
        dynamics,
        rules,
        (observations, actions),
        &terms,
        config,
        rng,
    )
}

/// The networks' part of [`step_particles`]: drift, σ, h(η) and η depend on
/// (s, a) only, so they run once per item (with ε = 0, s' is the mean). Rows
/// are independent: the server runs many requests' items as one call.
pub fn particle_terms(
    dynamics: &dyn BatchDynamics,
    observations: &[f32],
    actions: &[f32],
) -> ModelStep {
    let batch = observations.len() / dynamics.obs_dim();
    let states = dynamics.states_from_observations(observations);
    dynamics.step(&states, actions, &vec![0.0; batch * dynamics.noise_dim()])
}

/// The rest of [`step_particles`] from the items' `terms`: each particle's
/// noise (drawn from `rng`), its next state, reward and termination.
pub fn sample_particles(
    dynamics: &dyn BatchDynamics,
    rules: &Rules,
    (observations, actions): (&[f32], &[f32]),
    terms: &ModelStep,
    config: ParticleConfig,
    rng: &mut ChaCha8Rng,
) -> ParticleStep {
    let ParticleConfig {
        particles,
        penalty,
        noise_scale,
    } = config;
    let (obs_dim, act_dim) = (dynamics.obs_dim(), dynamics.act_dim());
    let state_dim = dynamics.state_dim();
    let batch = observations.len() / obs_dim;
    let rows = batch * particles;
    let noise_dim = dynamics.noise_dim();
    let states = dynamics.states_from_observations(observations);
    // Particle p of item b is row b·particles + p, drawn in that order.
    let noise = scaled_noise(rows * noise_dim, noise_scale, rng);
    let sqrt_dt = dynamics.dt().sqrt() as f32;
    // A model that draws more than its additive noise (an ensemble picking a
    // member per sample) steps every particle through its networks.
    let sampled = (noise_dim != state_dim)
        .then(|| step_every_particle(dynamics, &states, actions, particles, &noise));
    let columns = |values: &[f32]| observation_columns(values, state_dim, obs_dim);
    let mut out = ParticleStep {
        batch,
        particles,
        obs_dim,
        mean: columns(&terms.means),
        sigma: columns(&terms.sigma),
        h_eta: columns(&terms.h_eta),
        eta: terms.eta.clone(),
        next_states: Vec::with_capacity(rows * obs_dim),
        rewards: Vec::with_capacity(rows),
        penalized_rewards: Vec::with_capacity(rows),
        terminals: Vec::with_capacity(rows),
    };
    let mut next = vec![0.0; state_dim];
    for row in 0..rows {
        let b = row / particles.max(1);
        let item = b * state_dim..(b + 1) * state_dim;
        let noise = &noise[row * noise_dim..(row + 1) * noise_dim];
        match &sampled {
            Some(samples) => next.copy_from_slice(&samples[row * state_dim..(row + 1) * state_dim]),
            None => {
                for (d, next) in next.iter_mut().enumerate() {
                    *next = euler_maruyama(
                        terms.means[item.start + d],
                        terms.sigma[item.start + d],
                        terms.h_eta[item.start + d],
                        noise[d],
                        sqrt_dt,
                    );
                }
            }
        }
        let next_obs = &next[..obs_dim];
        let reward = if dynamics.learns_reward() {
            next[obs_dim]
        } else {
            rules.reward(
                &observations[b * obs_dim..(b + 1) * obs_dim],
                &actions[b * act_dim..(b + 1) * act_dim],
                next_obs,
            )
        };
        out.next_states.extend_from_slice(next_obs);
        out.rewards.push(reward);
        out.penalized_rewards
            .push(penalized_reward(reward, penalty, terms.eta[b]));
        out.terminals.push(rules.terminal(next_obs));
    }
    out
}

/// Each item's state and action repeated `particles` times, stepped with each particle's
/// `noise`: the next states `[b · p, state_dim]`.
fn step_every_particle(
    dynamics: &dyn BatchDynamics,
    states: &[f32],
    actions: &[f32],
    particles: usize,
    noise: &[f32],
) -> Vec<f32> {
    let repeat = |values: &[f32], width: usize| -> Vec<f32> {
        values
            .chunks_exact(width)
            .flat_map(|row| std::iter::repeat_n(row, particles).flatten().copied())
            .collect()
    };
    let (state_dim, act_dim) = (dynamics.state_dim(), dynamics.act_dim());
    dynamics
        .step(&repeat(states, state_dim), &repeat(actions, act_dim), noise)
        .next_states
}

/// The first `obs_dim` columns of each `state_dim`-wide row (NUNO^R's r_c dropped).
fn observation_columns(values: &[f32], state_dim: usize, obs_dim: usize) -> Vec<f32> {
    values
        .chunks_exact(state_dim)
        .flat_map(|row| &row[..obs_dim])
        .copied()
        .collect()
}
