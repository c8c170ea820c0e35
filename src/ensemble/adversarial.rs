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
use super::fused_trainer::{FusedTrainer, OutputTerm};
use super::model::{BoundedLogvar, GaussianEnsemble};
use super::trainer::{
    ADAM_EPSILON, EnsembleTrainer, LossTerms, MemberBatch, bounds_loss, member_nll, weight_decay,
};
use crate::infer::Kernel;
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

/// Transitions drawn for one adversarial step, with the (s, a) rows they
/// were drawn at: either kernel's step takes them.
pub struct AdversarialSample {
    observations: Vec<f32>,
    actions: Vec<f32>,
    /// ŝ', `[rows, obs_dim]`.
    pub next_observations: Vec<f32>,
    /// r̂, `[rows]`.
    pub rewards: Vec<f32>,
    /// log p(x̂) per row under the elites' mixture when drawn.
    log_probs: Vec<f32>,
}

impl AdversarialSample {
    /// log p(x̂) per row.
    pub fn log_probs(&self) -> &[f32] {
        &self.log_probs
    }

    /// x̂ = (ŝ', r̂), `[rows, obs_dim + 1]`.
    fn targets(&self) -> Vec<f32> {
        joined_targets(&self.next_observations, &self.rewards)
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

/// Who trains the members: burn's autodiff (the reference, and a GPU's path)
/// or the fused CPU kernels (`FusedTrainer`), held to it in tests/ensemble.rs.
enum Members {
    Burn {
        /// On the autodiff device.
        model: GaussianEnsemble,
        adam: Adam,
        state: AdamState,
    },
    Fused(FusedTrainer),
}

/// What both kernels read: the rows' layout, the scaler, the elites, the knobs.
struct Layout {
    scaler: Scaler,
    elites: Vec<usize>,
    obs_dim: usize,
    act_dim: usize,
    config: AdversarialConfig,
}

/// The ensemble as RAMBO trains it: the same members, scaler and elites as
/// the [`EnsembleDynamics`] it starts from, with its own Adam state, on the
/// kernel it was made for.
pub struct AdversarialEnsemble {
    members: Members,
    layout: Layout,
}

impl AdversarialEnsemble {
    /// `dynamics`' ensemble, trained on `kernel`'s path (burn's on `device`'s
    /// autodiff form).
    pub fn new(
        dynamics: &EnsembleDynamics,
        config: AdversarialConfig,
        kernel: Kernel,
        device: &Device,
    ) -> Self {
        let (model, scaler, elites) = dynamics.parts();
        let members = match kernel {
            Kernel::Fused => Members::Fused(FusedTrainer::new(
                model.clone(),
                LossTerms {
                    learning_rate: config.learning_rate,
                    weight_decay: config.weight_decay.clone(),
                    bounds_coef: config.logvar_loss_coef,
                },
            )),
            Kernel::Burn => Members::Burn {
                model: trainable_copy(model, &device.clone().autodiff()),
                adam: Adam::new(ADAM_EPSILON),
                state: AdamState::default(),
            },
        };
        let layout = Layout {
            scaler: scaler.clone(),
            elites: elites.to_vec(),
            obs_dim: dynamics.obs_dim(),
            act_dim: dynamics.act_dim(),
            config,
        };
        Self { members, layout }
    }

    /// The ensemble now, ready to step as `like` does (its kernel and uncertainty).
    pub fn dynamics(&self, like: &EnsembleDynamics) -> EnsembleDynamics {
        like.with_model(assign_params(like.parts().0.clone(), &self.model()))
    }

    /// The members' current weights (a checkpoint's).
    pub fn model(&self) -> GaussianEnsemble {
        match &self.members {
            Members::Burn { model, .. } => model.clone(),
            Members::Fused(trainer) => trainer.model(),
        }
    }

    /// Adam's state, moments by the ensemble's module paths (a checkpoint's;
    /// either kernel resumes the other's).
    pub fn optimizer_state(&self) -> AdamState {
        match &self.members {
            Members::Burn { state, .. } => state.clone(),
            Members::Fused(trainer) => trainer.optimizer_state(),
        }
    }

    /// Restores saved weights and Adam state (a checkpoint's).
    pub fn restore(&mut self, saved: &GaussianEnsemble, adam: AdamState) {
        match &mut self.members {
            Members::Burn { model, state, .. } => {
                *model = assign_params(model.clone(), saved);
                *state = adam;
            }
            Members::Fused(trainer) => trainer.restore(saved, adam),
        }
    }

    /// The elites at the rows on the host.
    fn host_predictions(&mut self, observations: &[f32], actions: &[f32]) -> HostElites {
        let layout = &self.layout;
        match &mut self.members {
            Members::Fused(trainer) => layout.fused_predictions(trainer, observations, actions),
            Members::Burn { model, .. } => {
                HostElites::from_graph(&layout.graph_predictions(model, observations, actions))
            }
        }
    }

    /// Draws x̂ for each (s, a) row from a random elite, with log p(x̂) under
    /// the elites' mixture.
    pub fn sample(
        &mut self,
        observations: &[f32],
        actions: &[f32],
        rng: &mut impl Rng,
    ) -> AdversarialSample {
        let (o, a) = (self.layout.obs_dim, self.layout.act_dim);
        let d = o + 1;
        let rows = observations.len() / o;
        let elites = self.host_predictions(observations, actions);
        let mut eps = Vec::new();
        fill_standard_normal(&mut eps, rows * d, rng);
        let mut drawn = Vec::with_capacity(rows * d);
        for r in 0..rows {
            let e = rng.random_range(0..elites.means.len());
            let (mean, logvar) = (&elites.means[e], &elites.logvars[e]);
            for k in r * d..(r + 1) * d {
                drawn.push(mean[k] + (0.5 * logvar[k]).exp() * eps[k]);
            }
        }
        AdversarialSample {
            observations: observations.to_vec(),
            actions: actions[..rows * a].to_vec(),
            next_observations: (drawn.chunks_exact(d))
                .flat_map(|row| row[..o].to_vec())
                .collect(),
            rewards: drawn.chunks_exact(d).map(|row| row[o]).collect(),
            log_probs: elites.mixture(&drawn).log_probs,
        }
    }

    /// log p((s', r) | s, a) under the elites' mixture now, per row.
    pub fn log_prob(
        &mut self,
        observations: &[f32],
        actions: &[f32],
        next_observations: &[f32],
        rewards: &[f32],
    ) -> Vec<f32> {
        let x = joined_targets(next_observations, rewards);
        let elites = self.host_predictions(observations, actions);
        elites.mixture(&x).log_probs
    }

    /// One Adam step on w_adv·mean(log p(x̂)·A) + L_sl, L_sl on the real
    /// transitions `real` (observations, actions, next observations, rewards).
    pub fn step(
        &mut self,
        sample: &AdversarialSample,
        advantage: &[f32],
        real: (&[f32], &[f32], &[f32], &[f32]),
    ) -> AdversarialLosses {
        let layout = &self.layout;
        let real = layout.real_rows(real);
        match &mut self.members {
            Members::Burn { model, adam, state } => {
                let (stepped, losses) =
                    layout.burn_step(model.clone(), (adam, state), (sample, advantage), real);
                *model = stepped;
                losses
            }
            Members::Fused(trainer) => layout.fused_step(trainer, (sample, advantage), real),
        }
    }
}

impl Layout {
    /// Normalised inputs `[rows, obs + act]` of (s, a) rows.
    fn inputs(&self, observations: &[f32], actions: &[f32]) -> Vec<f32> {
        let (o, a) = (self.obs_dim, self.act_dim);
        let rows = observations.len() / o;
        (self.scaler).inputs((observations, o), &actions[..rows * a], a)
    }

    /// Each row's (s, 0): what an elite's mean (Δs, r) is added to.
    fn base(&self, observations: &[f32]) -> Vec<f32> {
        (observations.chunks_exact(self.obs_dim))
            .flat_map(|s| s.iter().copied().chain([0.0]))
            .collect()
    }

    /// The real transitions as normalised inputs and targets (Δs, r).
    fn real_rows(
        &self,
        (obs, actions, next, rewards): (&[f32], &[f32], &[f32], &[f32]),
    ) -> MemberBatch {
        let o = self.obs_dim;
        let mut y = Vec::with_capacity(rewards.len() * (o + 1));
        for ((next, obs), &reward) in next.chunks_exact(o).zip(obs.chunks_exact(o)).zip(rewards) {
            push_target(&mut y, obs, next, reward);
        }
        MemberBatch {
            x: self.inputs(obs, actions),
            y,
        }
    }

    /// Each elite's mean (s + Δs, r) and log-variance at the rows, on burn's graph.
    fn graph_predictions(
        &self,
        model: &GaussianEnsemble,
        observations: &[f32],
        actions: &[f32],
    ) -> Vec<(Tensor<2>, Tensor<2>)> {
        let (d, width) = (self.obs_dim + 1, self.obs_dim + self.act_dim);
        let rows = observations.len() / self.obs_dim;
        let device = model.max_logvar.val().device();
        let x = self.inputs(observations, actions);
        let x = Tensor::<2>::from_data(TensorData::new(x, [rows, width]), &device);
        let base = self.base(observations);
        let base = Tensor::<2>::from_data(TensorData::new(base, [rows, d]), &device);
        (self.elites.iter())
            .map(|&m| {
                let (mean, logvar) = model.member(m, x.clone());
                (mean + base.clone(), logvar)
            })
            .collect()
    }

    /// The elites at the rows from the fused members' raw outputs.
    fn fused_predictions(
        &self,
        trainer: &mut FusedTrainer,
        observations: &[f32],
        actions: &[f32],
    ) -> HostElites {
        let raw = trainer.outputs(&self.elites, &self.inputs(observations, actions));
        RawElites::new(raw, &self.base(observations), trainer.bounds()).host
    }

    /// The step on burn's graph: `model` stepped, and the two terms.
    fn burn_step(
        &self,
        model: GaussianEnsemble,
        (adam, state): (&Adam, &mut AdamState),
        (sample, advantage): (&AdversarialSample, &[f32]),
        real: MemberBatch,
    ) -> (GaussianEnsemble, AdversarialLosses) {
        let (d, width) = (self.obs_dim + 1, self.obs_dim + self.act_dim);
        let elites = self.graph_predictions(&model, &sample.observations, &sample.actions);
        let device = model.max_logvar.val().device();
        let tensor = |values: Vec<f32>, width: usize| {
            let rows = values.len() / width;
            Tensor::<2>::from_data(TensorData::new(values, [rows, width]), &device)
        };
        let log_prob = mixture_log_prob(&elites, tensor(sample.targets(), d));
        let adversarial = (log_prob * tensor(advantage.to_vec(), 1)).mean();
        let (x, y) = (tensor(real.x, width), tensor(real.y, d));
        let supervised = (0..model.members.len()).fold(
            bounds_loss(&model, self.config.logvar_loss_coef),
            |loss, m| {
                loss + member_nll(&model, m, x.clone(), y.clone())
                    + weight_decay(&model.members[m], &self.config.weight_decay)
            },
        );
        let losses = AdversarialLosses {
            adversarial: to_f32_vec(adversarial.clone())[0],
            supervised: to_f32_vec(supervised.clone())[0],
        };
        let loss = adversarial * self.config.adv_weight + supervised;
        let grads = GradientsParams::from_grads(loss.backward(), &model);
        let model = adam.step_module(self.config.learning_rate, model, grads, state);
        (model, losses)
    }

    /// The same step by hand: the mixture's gradient by each elite's output
    /// on the sample's rows (`RawElites::gradient`), then one pass of every
    /// member over the real batch and, for the elites, those rows after it.
    fn fused_step(
        &self,
        trainer: &mut FusedTrainer,
        (sample, advantage): (&AdversarialSample, &[f32]),
        real: MemberBatch,
    ) -> AdversarialLosses {
        let inputs = self.inputs(&sample.observations, &sample.actions);
        let raw = trainer.outputs(&self.elites, &inputs);
        let elites = RawElites::new(raw, &self.base(&sample.observations), trainer.bounds());
        let targets = sample.targets();
        let mixture = elites.host.mixture(&targets);
        let rows = advantage.len().max(1) as f32;
        // ∂(w_adv·mean(log p·A))/∂log p_r = w_adv·A_r/rows.
        let weight = self.config.adv_weight as f32 / rows;
        let weights: Vec<f32> = advantage.iter().map(|a| weight * a).collect();
        let (grads, max, min) = elites.gradient((&targets, &mixture), &weights);
        let mut term = OutputTerm {
            rows: vec![None; trainer.member_count()],
            max,
            min,
        };
        for (&m, grad) in self.elites.iter().zip(grads) {
            term.rows[m] = Some((inputs.clone(), grad));
        }
        let supervised = trainer.step_with(&vec![real; term.rows.len()], Some(&term));
        let adversarial = (mixture.log_probs.iter().zip(advantage))
            .map(|(l, a)| l * a)
            .sum::<f32>()
            / rows;
        AdversarialLosses {
            adversarial,
            supervised: supervised as f32,
        }
    }
}

/// (s', r) rows, `[rows, obs_dim + 1]`.
fn joined_targets(next_observations: &[f32], rewards: &[f32]) -> Vec<f32> {
    let o = next_observations.len() / rewards.len().max(1);
    (next_observations.chunks_exact(o.max(1)))
        .zip(rewards)
        .flat_map(|(s, &r)| s.iter().copied().chain([r]))
        .collect()
}

/// A copy of `model` whose parameters track gradients on `device`.
fn trainable_copy(model: &GaussianEnsemble, device: &Device) -> GaussianEnsemble {
    let layers = &model.members[0].layers;
    let hidden: Vec<usize> = (layers[..layers.len() - 1].iter())
        .map(|layer| layer.weight.val().dims()[1])
        .collect();
    let d_in = layers[0].weight.val().dims()[0];
    let d_out = model.max_logvar.val().dims()[0];
    // Drawn (any seed: every value is then overwritten) so the copy's parameters track gradients.
    let fresh = seeded_init(device, 0, || {
        GaussianEnsemble::init(
            d_in,
            d_out,
            &hidden,
            model.members.len(),
            (0.0, 0.0),
            device,
        )
    });
    assign_params(fresh, model)
}

/// The elites' Gaussians at some rows, on the host: means (s + Δs, r) and
/// bounded log-variances `[rows, d]` each.
struct HostElites {
    /// Values per row: the state's and the reward.
    d: usize,
    means: Vec<Vec<f32>>,
    logvars: Vec<Vec<f32>>,
}

/// The same from the fused members' raw outputs, with ∂log σ²/∂(raw, max,
/// min) per value: what the gradient by those outputs needs.
struct RawElites {
    host: HostElites,
    derivatives: Vec<Vec<(f32, f32, f32)>>,
}

/// log p per row, and each elite's share of it (its responsibility π).
struct Mixture {
    log_probs: Vec<f32>,
    /// `[rows, elites]`.
    shares: Vec<f32>,
}

impl RawElites {
    fn new(raw: Vec<Vec<f32>>, base: &[f32], (max, min): (&[f32], &[f32])) -> Self {
        let d = max.len();
        let mut elites = Self {
            host: HostElites {
                d,
                means: Vec::new(),
                logvars: Vec::new(),
            },
            derivatives: Vec::new(),
        };
        for out in raw {
            let (mut mean, mut logvar, mut derivative) = (Vec::new(), Vec::new(), Vec::new());
            for (row, base) in out.chunks_exact(2 * d).zip(base.chunks_exact(d)) {
                for j in 0..d {
                    let bounded = BoundedLogvar::of(row[d + j], max[j], min[j]);
                    mean.push(row[j] + base[j]);
                    logvar.push(bounded.value);
                    derivative.push((bounded.d_raw, bounded.d_max, bounded.d_min));
                }
            }
            elites.host.means.push(mean);
            elites.host.logvars.push(logvar);
            elites.derivatives.push(derivative);
        }
        elites
    }

    /// The gradient of Σ_r c_r·log p_r(x_r) by each elite's raw output
    /// (`[rows, 2·d]`) and by the bounds (max, min), from the shares π:
    /// ∂/∂μ = c·π·(x − μ)/σ², ∂/∂log σ² = −½·c·π·(1 − (x − μ)²/σ²), the
    /// latter through the bounds.
    fn gradient(
        &self,
        (x, mixture): (&[f32], &Mixture),
        weights: &[f32],
    ) -> (Vec<Vec<f32>>, Vec<f32>, Vec<f32>) {
        let (host, elites) = (&self.host, self.host.means.len());
        let d = host.d;
        let (mut grad_max, mut grad_min) = (vec![0.0f32; d], vec![0.0f32; d]);
        let grads = (0..elites)
            .map(|e| {
                let mut grad = vec![0.0f32; weights.len() * 2 * d];
                for (r, &c) in weights.iter().enumerate() {
                    let c = c * mixture.shares[r * elites + e];
                    for j in 0..d {
                        let k = r * d + j;
                        let diff = x[k] - host.means[e][k];
                        let inverse_variance = (-host.logvars[e][k]).exp();
                        let d_logvar = -0.5 * c * (1.0 - diff * diff * inverse_variance);
                        let (d_raw, d_max, d_min) = self.derivatives[e][k];
                        grad[r * 2 * d + j] = c * diff * inverse_variance;
                        grad[r * 2 * d + d + j] = d_logvar * d_raw;
                        grad_max[j] += d_logvar * d_max;
                        grad_min[j] += d_logvar * d_min;
                    }
                }
                grad
            })
            .collect();
        (grads, grad_max, grad_min)
    }
}

impl HostElites {
    fn from_graph(elites: &[(Tensor<2>, Tensor<2>)]) -> Self {
        Self {
            d: elites[0].0.dims()[1],
            means: elites.iter().map(|(m, _)| to_f32_vec(m.clone())).collect(),
            logvars: elites.iter().map(|(_, l)| to_f32_vec(l.clone())).collect(),
        }
    }

    /// log (1/E)·Σ_e Π_d N(x_d | μ_e, σ_e) per row of `x` (`[rows, d]`), as a
    /// log-sum-exp over the elites (as [`mixture_log_prob`]), and each elite's share.
    fn mixture(&self, x: &[f32]) -> Mixture {
        let (d, elites) = (self.d, self.means.len());
        let rows = x.len() / d;
        let ln_two_pi = (2.0 * std::f32::consts::PI).ln();
        let mut out = Mixture {
            log_probs: Vec::with_capacity(rows),
            shares: Vec::with_capacity(rows * elites),
        };
        let mut each = vec![0.0f32; elites];
        for r in 0..rows {
            for (e, l) in each.iter_mut().enumerate() {
                *l = (r * d..(r + 1) * d)
                    .map(|k| {
                        let diff = x[k] - self.means[e][k];
                        let logvar = self.logvars[e][k];
                        -0.5 * (diff * diff * (-logvar).exp() + logvar + ln_two_pi)
                    })
                    .sum();
            }
            let top = each.iter().copied().fold(f32::NEG_INFINITY, f32::max);
            let log_sum = top + each.iter().map(|l| (l - top).exp()).sum::<f32>().ln();
            out.log_probs.push(log_sum - (elites as f32).ln());
            out.shares.extend(each.iter().map(|l| (l - log_sum).exp()));
        }
        out
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
