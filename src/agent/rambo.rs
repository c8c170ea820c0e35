//! RAMBO (Rigter et al., 2022; OfflineRL-Kit's `rambo.py` / `run_rambo.py`):
//! MOPO's ensemble and SAC loop with no reward penalty; instead, every
//! `adversary_every` policy steps the ensemble itself is trained against the
//! policy ([`AdversarialEnsemble`]) on short chains from dataset states, and
//! the actor starts from behaviour cloning:
//!
//! ```text
//! before any update: the actor cloned on the data (MSE of sampled actions), bc_epochs passes
//! every adversary_every steps, adversary_steps model steps in all, along chains of
//! 256 dataset states, then up to h times:
//!     a ~ π(·|s); x̂ = (ŝ', r̂) from a random elite; d from the task's termination rule
//!     A = r̂ + γ(1 − d)·min_j Q_j(ŝ', π_det(ŝ')) − min_j Q_j(s, a), standardised
//!     one Adam step on w_adv·mean(log p(x̂)·A) + L_sl; s ← ŝ' where not terminal
//! ```
//!
//! The critics in A are the current ones (not the targets), the entropy is
//! left out of A (`include_ent_in_adv` off), as in OfflineRL-Kit.

use burn::config::Config;
use burn::module::Module;
use burn::optim::GradientsParams;
use burn::tensor::{Tensor, TensorData};
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;

use super::sac::Sac;
use crate::data::{Dataset, StartStateSampler, TransitionSampler};
use crate::ensemble::{AdversarialConfig, AdversarialEnsemble, AdversarialLosses};
use crate::envs::Rules;
use crate::nn::{AdamState, normal, rows_tensor, to_f32_vec};

/// RAMBO's knobs beyond the loop's (OfflineRL-Kit's `run_rambo.py`).
#[derive(Config, Debug, PartialEq)]
pub struct RamboConfig {
    pub adversary: AdversarialConfig,
    /// Policy steps between adversarial phases (`adv_train_steps`' period).
    #[config(default = 1000)]
    pub adversary_every: usize,
    /// Adversarial model steps per phase.
    #[config(default = 1000)]
    pub adversary_steps: usize,
    /// Dataset states each adversarial chain starts from (`adv_rollout_batch_size`).
    #[config(default = 256)]
    pub adversary_batch: usize,
    /// Passes of behaviour cloning over the dataset before any update.
    #[config(default = 50)]
    pub bc_epochs: usize,
    #[config(default = 1e-4)]
    pub bc_lr: f64,
    #[config(default = 256)]
    pub bc_batch: usize,
}

/// A's standardisation guard, OfflineRL-Kit's.
const ADVANTAGE_EPSILON: f32 = 1e-6;

/// (A − mean A)/(std A + 1e-6), torch's std (n − 1).
pub fn standardise(advantage: &mut [f32]) {
    let n = advantage.len() as f32;
    if n < 2.0 {
        return;
    }
    let mean = advantage.iter().sum::<f32>() / n;
    let std = (advantage.iter().map(|a| (a - mean).powi(2)).sum::<f32>() / (n - 1.0)).sqrt();
    for a in advantage.iter_mut() {
        *a = (*a - mean) / (std + ADVANTAGE_EPSILON);
    }
}

/// A = r̂ + γ(1 − d)·min_j Q_j(ŝ', π_det(ŝ')) − min_j Q_j(s, a) per row, with
/// the current critics, before standardising.
pub fn advantages(
    sac: &Sac,
    (obs, actions): (&[f32], &[f32]),
    (next, rewards, terminals): (&[f32], &[f32], &[f32]),
) -> Vec<f32> {
    let c = &sac.actor.config;
    let rows = rewards.len();
    let device = sac.device().clone().inner();
    let (actor, critic) = (sac.actor.valid(), sac.critic.valid());
    let next = rows_tensor(next, c.obs_dim, &device);
    let next_q = to_f32_vec(critic.min_q(next.clone(), actor.mean_action(next)));
    let baseline = to_f32_vec(critic.min_q(
        rows_tensor(obs, c.obs_dim, &device),
        rows_tensor(actions, c.act_dim, &device),
    ));
    let gamma = sac.config.gamma as f32;
    (0..rows)
        .map(|r| rewards[r] + (1.0 - terminals[r]) * gamma * next_q[r] - baseline[r])
        .collect()
}

/// One adversarial phase: `adversary_steps` model steps in all, taken along
/// chains of up to `horizon` steps from dataset states (OfflineRL-Kit counts
/// every step of a chain, and stops mid-chain at the count), the ensemble
/// stepped at each; the mean losses.
pub fn adversarial_phase(
    adversary: &mut AdversarialEnsemble,
    sac: &Sac,
    (dataset, rules): (&Dataset, &Rules),
    (config, horizon): (&RamboConfig, usize),
    rng: &mut ChaCha8Rng,
) -> AdversarialLosses {
    let (o, a) = (dataset.obs_dim(), dataset.act_dim());
    let actor = sac.actor.valid();
    let device = sac.device().clone().inner();
    let mut losses = Vec::new();
    // A chain of no states takes no step: nothing to count towards the phase.
    while losses.len() < config.adversary_steps && config.adversary_batch > 0 {
        let mut obs = StartStateSampler::new(dataset).sample(config.adversary_batch, rng);
        for _ in 0..horizon {
            let rows = obs.len() / o;
            if rows == 0 || losses.len() == config.adversary_steps {
                break;
            }
            let states = Tensor::<2>::from_data(TensorData::new(obs.clone(), [rows, o]), &device);
            let actions = to_f32_vec(actor.sample(states, normal([rows, a], rng, &device)).action);
            let sample = adversary.sample(&obs, &actions, rng);
            let next = sample.next_observations.clone();
            let terminals: Vec<f32> = next
                .chunks_exact(o)
                .map(|s| f32::from(u8::from(rules.terminal(s))))
                .collect();
            let mut advantage =
                advantages(sac, (&obs, &actions), (&next, &sample.rewards, &terminals));
            standardise(&mut advantage);
            let real = TransitionSampler::new(dataset).sample(config.adversary_batch, rng);
            losses.push(adversary.step(
                &sample,
                &advantage,
                (
                    &real.observations,
                    &real.actions,
                    &real.next_observations,
                    &real.rewards,
                ),
            ));
            obs = next
                .chunks_exact(o)
                .zip(&terminals)
                .filter(|(_, d)| **d == 0.0)
                .flat_map(|(s, _)| s.to_vec())
                .collect();
        }
    }
    AdversarialLosses::mean(&losses).unwrap_or(AdversarialLosses {
        adversarial: 0.0,
        supervised: 0.0,
    })
}

/// RAMBO's behaviour-cloning start: `bc_epochs` shuffled passes over the
/// dataset, each batch one Adam step (its own state) on the actor's
/// mean ‖a_sampled(s) − a‖² (the reparameterised sample, as `rsample`);
/// returns the last pass's mean loss.
pub fn behaviour_clone(
    sac: &mut Sac,
    dataset: &Dataset,
    config: &RamboConfig,
    rng: &mut ChaCha8Rng,
) -> f32 {
    let (o, a) = (dataset.obs_dim(), dataset.act_dim());
    let device = sac.device().clone();
    let adam = sac.optimizer();
    let mut state = AdamState::default();
    let mut order: Vec<usize> = (0..dataset.len()).collect();
    let mut last = 0.0;
    for _ in 0..config.bc_epochs {
        order.shuffle(rng);
        let mut sum = 0.0;
        let chunks = order.chunks(config.bc_batch.max(1));
        let count = chunks.len();
        for chunk in chunks {
            let rows = chunk.len();
            let gather = |width: usize, row: &dyn Fn(usize) -> Vec<f32>| {
                let values: Vec<f32> = chunk.iter().flat_map(|&i| row(i)).collect();
                Tensor::<2>::from_data(TensorData::new(values, [rows, width]), &device)
            };
            let obs = gather(o, &|i| dataset.observations.row(i).to_vec());
            let target = gather(a, &|i| dataset.actions.row(i).to_vec());
            let noise = normal([rows, a], rng, &device);
            let loss = (sac.actor.sample(obs, noise).action - target)
                .powi_scalar(2)
                .mean();
            sum += to_f32_vec(loss.clone())[0];
            let grads = GradientsParams::from_grads(loss.backward(), &sac.actor);
            sac.actor = adam.step_module(config.bc_lr, sac.actor.clone(), grads, &mut state);
        }
        last = sum / count.max(1) as f32;
    }
    last
}

#[cfg(test)]
mod tests {
    use super::standardise;

    #[test]
    fn advantages_are_standardised_with_the_unbiased_std() {
        // A = 1, 2, 3, 6: mean 3, squares 4 + 1 + 0 + 9 = 14, /3 → std √(14/3).
        let mut a = [1.0f32, 2.0, 3.0, 6.0];
        standardise(&mut a);
        let std = (14.0f32 / 3.0).sqrt() + 1e-6;
        for (got, raw) in a.iter().zip([1.0f32, 2.0, 3.0, 6.0]) {
            assert!((got - (raw - 3.0) / std).abs() < 1e-6, "{a:?}");
        }
    }
}
