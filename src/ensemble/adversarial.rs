//! RAMBO's adversarial model update (Rigter et al., 2022; OfflineRL-Kit's
//! `rambo.py`, `dynamics_step_and_forward`): the ensemble is trained, between
//! the policy's updates, to make transitions the policy values highly less
//! likely, while a supervised term keeps it on the data:
//!
//! ```text
//! x̂ = (ŝ', r̂) ~ N(μ_e(s, a), σ_e(s, a)), e a random elite per row (no gradient)
//! log p(x̂) = log (1/|E|)·Σ_{e ∈ elites} Π_d N(x̂_d | μ_e, σ_e)
//! L = w_adv·mean(log p(x̂)·A) + L_sl,   A the policy's standardised advantage of x̂
//! L_sl = Σ_members NLL on a real batch + weight decay + c·(Σ max log σ² − Σ min log σ²)
//! ```
//!
//! The advantage is the caller's (it needs the policy and critics); this
//! module samples, then steps on the sample with the advantage given.

use burn::config::Config;
use burn::optim::GradientsParams;
use burn::tensor::{Device, Tensor, TensorData};
use rand::Rng;

use super::dynamics::EnsembleDynamics;
use super::fit::{Scaler, push_target};
use super::model::GaussianEnsemble;
use super::trainer::{ADAM_EPSILON, bounds_loss, member_nll, weight_decay};
use crate::nn::{Adam, AdamState, assign_params, fill_standard_normal, seeded_init, to_f32_vec};
use crate::shared::BatchDynamics;

/// The adversarial update's knobs (OfflineRL-Kit's `run_rambo.py`).
#[derive(Config, Debug, PartialEq)]
pub struct AdversarialConfig {
    /// w_adv, the adversarial term's weight (per task).
    pub adv_weight: f64,
    /// Adam's learning rate for the whole loss (`adv_lr`).
    #[config(default = 3e-4)]
    pub learning_rate: f64,
    /// c, the log-variance bounds' coefficient in L_sl (RAMBO's 1e-3).
    #[config(default = 1e-3)]
    pub logvar_loss_coef: f64,
    /// Each layer's weight-decay coefficient in L_sl (MOPO's ensemble's).
    #[config(default = "vec![2.5e-5, 5e-5, 7.5e-5, 7.5e-5, 1e-4]")]
    pub weight_decay: Vec<f64>,
}

/// Transitions drawn for one adversarial step, and the graph to their
/// log-likelihood under the elites' mixture.
pub struct AdversarialSample {
    /// ŝ', `[rows, obs_dim]`.
    pub next_observations: Vec<f32>,
    /// r̂, `[rows]`.
    pub rewards: Vec<f32>,
    /// log p(x̂), `[rows, 1]`, on the autodiff graph.
    log_prob: Tensor<2>,
}

impl AdversarialSample {
    /// log p(x̂) per row, off the graph.
    pub fn log_probs(&self) -> Vec<f32> {
        to_f32_vec(self.log_prob.clone())
    }
}

/// One step's two terms.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AdversarialLosses {
    /// mean(log p(x̂)·A), before w_adv.
    pub adversarial: f32,
    pub supervised: f32,
}

impl AdversarialLosses {
    /// The mean of each term over `losses`; `None` for none.
    pub fn mean(losses: &[AdversarialLosses]) -> Option<AdversarialLosses> {
        let n = losses.len() as f32;
        (!losses.is_empty()).then(|| AdversarialLosses {
            adversarial: losses.iter().map(|l| l.adversarial).sum::<f32>() / n,
            supervised: losses.iter().map(|l| l.supervised).sum::<f32>() / n,
        })
    }
}

/// The ensemble as RAMBO trains it: the same members, scaler and elites as
/// the [`EnsembleDynamics`] it starts from, on an autodiff device, with its
/// own Adam state.
pub struct AdversarialEnsemble {
    model: GaussianEnsemble,
    scaler: Scaler,
    elites: Vec<usize>,
    obs_dim: usize,
    act_dim: usize,
    config: AdversarialConfig,
    adam: Adam,
    pub state: AdamState,
}

impl AdversarialEnsemble {
    /// `dynamics`' ensemble, trainable on `device`'s autodiff form.
    pub fn new(dynamics: &EnsembleDynamics, config: AdversarialConfig, device: &Device) -> Self {
        let device = &device.clone().autodiff();
        let (model, scaler, elites) = dynamics.parts();
        let hidden: Vec<usize> = model.members[0].layers[..model.members[0].layers.len() - 1]
            .iter()
            .map(|layer| layer.weight.val().dims()[1])
            .collect();
        let (obs_dim, act_dim) = (dynamics.obs_dim(), dynamics.act_dim());
        // Drawn (any seed: every value is then overwritten) so the copy's parameters track gradients.
        let fresh = seeded_init(device, 0, || {
            GaussianEnsemble::init(
                obs_dim + act_dim,
                obs_dim + 1,
                &hidden,
                model.members.len(),
                (0.0, 0.0),
                device,
            )
        });
        Self {
            model: assign_params(fresh, model),
            scaler: scaler.clone(),
            elites: elites.to_vec(),
            obs_dim,
            act_dim,
            config,
            adam: Adam::new(ADAM_EPSILON),
            state: AdamState::default(),
        }
    }

    /// The ensemble now, ready to step as `like` does (its kernel and uncertainty).
    pub fn dynamics(&self, like: &EnsembleDynamics) -> EnsembleDynamics {
        like.with_model(assign_params(like.parts().0.clone(), &self.model))
    }

    /// The members' current weights (a checkpoint's).
    pub fn model(&self) -> &GaussianEnsemble {
        &self.model
    }

    /// Restores saved weights and Adam state (a checkpoint's).
    pub fn restore(&mut self, model: &GaussianEnsemble, state: AdamState) {
        self.model = assign_params(self.model.clone(), model);
        self.state = state;
    }

    /// Normalised inputs `[rows, obs + act]` of (s, a) rows.
    fn inputs(&self, observations: &[f32], actions: &[f32]) -> Tensor<2> {
        let (o, a) = (self.obs_dim, self.act_dim);
        let rows = observations.len() / o;
        let x = self
            .scaler
            .inputs((observations, o), &actions[..rows * a], a);
        let device = self.model.max_logvar.val().device();
        Tensor::from_data(TensorData::new(x, [rows, o + a]), &device)
    }

    /// Each elite's mean (s + Δs, r) and log-variance at the rows, on the graph.
    fn elite_predictions(
        &self,
        observations: &[f32],
        actions: &[f32],
    ) -> Vec<(Tensor<2>, Tensor<2>)> {
        let (o, d) = (self.obs_dim, self.obs_dim + 1);
        let rows = observations.len() / o;
        let x = self.inputs(observations, actions);
        let base: Vec<f32> = observations
            .chunks_exact(o)
            .flat_map(|s| s.iter().copied().chain([0.0]))
            .collect();
        let base = Tensor::<2>::from_data(TensorData::new(base, [rows, d]), &x.device());
        (self.elites.iter())
            .map(|&m| {
                let (mean, logvar) = self.model.member(m, x.clone());
                (mean + base.clone(), logvar)
            })
            .collect()
    }

    /// Draws x̂ for each (s, a) row from a random elite and keeps the graph to
    /// log p(x̂) under the elites' mixture.
    pub fn sample(
        &self,
        observations: &[f32],
        actions: &[f32],
        rng: &mut impl Rng,
    ) -> AdversarialSample {
        let (o, d) = (self.obs_dim, self.obs_dim + 1);
        let rows = observations.len() / o;
        let elites = self.elite_predictions(observations, actions);
        let host: Vec<(Vec<f32>, Vec<f32>)> = (elites.iter())
            .map(|(mean, logvar)| (to_f32_vec(mean.clone()), to_f32_vec(logvar.clone())))
            .collect();
        let mut eps = Vec::new();
        fill_standard_normal(&mut eps, rows * d, rng);
        let mut drawn = Vec::with_capacity(rows * d);
        for r in 0..rows {
            let (mean, logvar) = &host[rng.random_range(0..host.len())];
            for k in r * d..(r + 1) * d {
                drawn.push(mean[k] + (0.5 * logvar[k]).exp() * eps[k]);
            }
        }
        let device = elites[0].0.device();
        let target = Tensor::<2>::from_data(TensorData::new(drawn.clone(), [rows, d]), &device);
        AdversarialSample {
            next_observations: drawn
                .chunks_exact(d)
                .flat_map(|row| row[..o].to_vec())
                .collect(),
            rewards: drawn.chunks_exact(d).map(|row| row[o]).collect(),
            log_prob: mixture_log_prob(&elites, target),
        }
    }

    /// log p((s', r) | s, a) under the elites' mixture now, per row, off the graph.
    pub fn log_prob(
        &self,
        observations: &[f32],
        actions: &[f32],
        next_observations: &[f32],
        rewards: &[f32],
    ) -> Vec<f32> {
        let (o, d) = (self.obs_dim, self.obs_dim + 1);
        let rows = rewards.len();
        let elites = self.elite_predictions(observations, actions);
        let x: Vec<f32> = (0..rows)
            .flat_map(|r| {
                next_observations[r * o..(r + 1) * o]
                    .iter()
                    .copied()
                    .chain([rewards[r]])
            })
            .collect();
        let x = Tensor::<2>::from_data(TensorData::new(x, [rows, d]), &elites[0].0.device());
        to_f32_vec(mixture_log_prob(&elites, x))
    }

    /// One Adam step on w_adv·mean(log p(x̂)·A) + L_sl, L_sl on the real
    /// transitions `real` (observations, actions, next observations, rewards).
    pub fn step(
        &mut self,
        sample: AdversarialSample,
        advantage: &[f32],
        real: (&[f32], &[f32], &[f32], &[f32]),
    ) -> AdversarialLosses {
        let device = sample.log_prob.device();
        let rows = advantage.len();
        let advantage =
            Tensor::<2>::from_data(TensorData::new(advantage.to_vec(), [rows, 1]), &device);
        let adversarial = (sample.log_prob * advantage).mean();
        let supervised = self.supervised_loss(real);
        let values = (
            to_f32_vec(adversarial.clone())[0],
            to_f32_vec(supervised.clone())[0],
        );
        let loss = adversarial * self.config.adv_weight + supervised;
        let grads = GradientsParams::from_grads(loss.backward(), &self.model);
        self.model = self.adam.step_module(
            self.config.learning_rate,
            self.model.clone(),
            grads,
            &mut self.state,
        );
        AdversarialLosses {
            adversarial: values.0,
            supervised: values.1,
        }
    }

    /// L_sl: every member's NLL on the same real batch, weight decay and the
    /// bounds' term.
    fn supervised_loss(
        &self,
        (obs, actions, next, rewards): (&[f32], &[f32], &[f32], &[f32]),
    ) -> Tensor<1> {
        let (o, d) = (self.obs_dim, self.obs_dim + 1);
        let rows = rewards.len();
        let x = self.inputs(obs, actions);
        let mut y = Vec::with_capacity(rows * d);
        for ((next, obs), &reward) in next.chunks_exact(o).zip(obs.chunks_exact(o)).zip(rewards) {
            push_target(&mut y, obs, next, reward);
        }
        let y = Tensor::<2>::from_data(TensorData::new(y, [rows, d]), &x.device());
        let model = &self.model;
        (0..model.members.len()).fold(
            bounds_loss(model, self.config.logvar_loss_coef),
            |loss, m| {
                loss + member_nll(model, m, x.clone(), y.clone())
                    + weight_decay(&model.members[m], &self.config.weight_decay)
            },
        )
    }
}

/// log (1/E)·Σ_e Π_d N(x_d | μ_e, σ_e) per row, as a log-sum-exp over the
/// elites (OfflineRL-Kit exponentiates in f64; the log-sum-exp is the same
/// value without underflow).
fn mixture_log_prob(elites: &[(Tensor<2>, Tensor<2>)], x: Tensor<2>) -> Tensor<2> {
    let ln_two_pi = (2.0 * std::f64::consts::PI).ln();
    let per_elite: Vec<Tensor<2>> = (elites.iter())
        .map(|(mean, logvar)| {
            let z = (x.clone() - mean.clone()).powi_scalar(2) * logvar.clone().neg().exp();
            ((z + logvar.clone()) + ln_two_pi).sum_dim(1) * -0.5
        })
        .collect();
    let all = Tensor::cat(per_elite, 1);
    let max = all.clone().max_dim(1).detach();
    (all - max.clone()).exp().sum_dim(1).log() + max - (elites.len() as f64).ln()
}
