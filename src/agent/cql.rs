//! CQL (Kumar et al., 2020) as OfflineRL-Kit's `cql.py` runs it: SAC (actor
//! first, then α, then the critics) with a deterministic backup and a
//! conservative term added to each critic's loss,
//!
//! ```text
//! β·T·mean_rows LSE_T(X) − β·mean Q_i(s, a),   X per repeated row of N = 10:
//!   Q_i(s, ã) − log π(ã|s),     ã ~ π(·|s)
//!   Q_i(s, ã') − log π(ã'|s'),  ã' ~ π(·|s')   (Q at s, as the reference)
//!   Q_i(s, u) − log 0.5^|A|,    u ~ U[−1, 1]^|A|  (log π's detached)
//! ```
//!
//! The log-sum-exp runs over the three sources of each of the B·N repeated
//! rows, then a mean over them (OfflineRL-Kit concatenates three `(B·N, 1)`
//! tensors on dim 1), not over all 3N samples of a state as the paper's form.
//! The Lagrange variant (off in OfflineRL-Kit's defaults) is not here.

use burn::config::Config;
use burn::module::Module;
use burn::optim::GradientsParams;
use burn::tensor::{Device, Tensor, TensorData};
use rand::Rng;
use rand_chacha::ChaCha8Rng;

use super::actor::ActorConfig;
use super::sac::{Sac, SacConfig, SacLosses};
use crate::nn::{Initialised, normal, polyak_update, rows_tensor};
use crate::shared::TransitionBatch;

/// CQL's hyperparameters (OfflineRL-Kit's `run_cql.py`).
#[derive(Config, Debug, PartialEq)]
pub struct CqlConfig {
    /// SAC's settings: [256, 256, 256] networks, actor lr 1e-4, critic 3e-4, α lr 1e-4.
    #[config(default = "CqlConfig::kit_sac()")]
    pub sac: SacConfig,
    #[config(default = "ConservativeTerm::new()")]
    pub term: ConservativeTerm,
}

/// The conservative term's settings (CQL's, and COMBO's on model rollouts).
#[derive(Config, Debug, PartialEq)]
pub struct ConservativeTerm {
    /// β, the term's weight (CQL: 5 for every D4RL task; COMBO per task).
    #[config(default = 5.0)]
    pub cql_weight: f64,
    /// T, the log-sum-exp's temperature.
    #[config(default = 1.0)]
    pub temperature: f64,
    /// N, sampled actions per source and state.
    #[config(default = 10)]
    pub num_repeat_actions: usize,
}

impl CqlConfig {
    /// OfflineRL-Kit's `run_cql.py` SAC settings.
    pub fn kit_sac() -> SacConfig {
        SacConfig::new()
            .with_actor_hidden(vec![256, 256, 256])
            .with_critic_hidden(vec![256, 256, 256])
            .with_actor_lr(1e-4)
            .with_alpha_lr(1e-4)
    }
}

/// The agent: SAC's networks with CQL's update.
pub struct Cql {
    pub config: CqlConfig,
    pub sac: Sac,
}

impl Initialised for Cql {
    fn draw_parameters(&self) {
        self.sac.draw_parameters();
    }
}

/// The conservative term's samples for a batch: ε for π at s and at s', and
/// the uniform actions, each `[B·N, act_dim]`.
pub struct CqlSamples {
    pub noise_at_state: Tensor<2>,
    pub noise_at_next: Tensor<2>,
    pub uniform: Tensor<2>,
}

impl Cql {
    pub fn new(actor: ActorConfig, config: CqlConfig, device: &Device) -> Self {
        Self {
            sac: Sac::new(actor, config.sac.clone(), device),
            config,
        }
    }

    pub fn device(&self) -> &Device {
        self.sac.device()
    }

    /// Each critic's conservative term on `obs` (every row a dataset row).
    pub fn conservative_terms(
        &self,
        obs: Tensor<2>,
        next_obs: Tensor<2>,
        actions: Tensor<2>,
        samples: CqlSamples,
    ) -> (Tensor<1>, Tensor<1>) {
        let rows = obs.dims()[0];
        (self.config.term).terms(&self.sac, obs, next_obs, actions, samples, rows)
    }

    /// One update on `batch`, every row a dataset row.
    pub fn update(&mut self, batch: &TransitionBatch, rng: &mut ChaCha8Rng) -> SacLosses {
        let rows = batch.rewards.len();
        self.config.term.update(&mut self.sac, batch, rows, rng)
    }
}

impl ConservativeTerm {
    /// Draws the term's samples for `rows` states on `device`.
    pub fn draw_samples(
        &self,
        act_dim: usize,
        rows: usize,
        rng: &mut ChaCha8Rng,
        device: &Device,
    ) -> CqlSamples {
        let n = rows * self.num_repeat_actions;
        let uniform: Vec<f32> = (0..n * act_dim)
            .map(|_| rng.random_range(-1.0f32..1.0))
            .collect();
        CqlSamples {
            noise_at_state: normal([n, act_dim], rng, device),
            noise_at_next: normal([n, act_dim], rng, device),
            uniform: Tensor::from_data(TensorData::new(uniform, [n, act_dim]), device),
        }
    }

    /// Each critic's term, β·(T·mean LSE_T(X) − mean Q_i(s, a)), as the module
    /// doc says: the LSE over every row of `obs` (COMBO's ρ: the mixed batch),
    /// the data term over its first `data_rows` (the real ones).
    ///
    /// # Shapes
    /// - `obs`, `next_obs`: `[B, obs_dim]`, `actions`: `[B, act_dim]`; samples `[B·N, act_dim]`
    pub fn terms(
        &self,
        sac: &Sac,
        obs: Tensor<2>,
        next_obs: Tensor<2>,
        actions: Tensor<2>,
        samples: CqlSamples,
        data_rows: usize,
    ) -> (Tensor<1>, Tensor<1>) {
        let repeat = self.num_repeat_actions;
        let repeated = |x: Tensor<2>| {
            let [b, w] = x.dims();
            x.unsqueeze_dim::<3>(1)
                .repeat_dim(1, repeat)
                .reshape([b * repeat, w])
        };
        let (obs_n, next_n) = (repeated(obs.clone()), repeated(next_obs));
        let at_state = sac.actor.sample(obs_n.clone(), samples.noise_at_state);
        let at_next = sac.actor.sample(next_n, samples.noise_at_next);
        let act_dim = sac.actor.config.act_dim as f32;
        let uniform_log_density = act_dim * 0.5f32.ln();
        let critic = &sac.critic;
        let (pi1, pi2) = critic.forward(obs_n.clone(), at_state.action);
        let (next1, next2) = critic.forward(obs_n.clone(), at_next.action);
        let (rand1, rand2) = critic.forward(obs_n, samples.uniform);
        let (log_pi, log_pi_next) = (at_state.log_prob.detach(), at_next.log_prob.detach());
        let (data1, data2) =
            critic.forward(obs.narrow(0, 0, data_rows), actions.narrow(0, 0, data_rows));
        let temperature = self.temperature;
        let term = |pi: Tensor<2>, next: Tensor<2>, random: Tensor<2>, data: Tensor<2>| {
            let x = Tensor::cat(
                vec![
                    pi - log_pi.clone(),
                    next - log_pi_next.clone(),
                    random - uniform_log_density,
                ],
                1,
            );
            let lse = log_sum_exp_rows(x / temperature) * temperature;
            (lse.mean() - data.mean()) * self.cql_weight
        };
        (
            term(pi1, next1, rand1, data1),
            term(pi2, next2, rand2, data2),
        )
    }

    /// One update of `sac` on `batch` whose first `data_rows` rows are real:
    /// actor, α, then the critics with the term, then the Polyak targets.
    pub fn update(
        &self,
        sac: &mut Sac,
        batch: &TransitionBatch,
        data_rows: usize,
        rng: &mut ChaCha8Rng,
    ) -> SacLosses {
        let c = &sac.actor.config;
        let (obs_dim, act_dim) = (c.obs_dim, c.act_dim);
        let b = batch.rewards.len();
        let device = sac.device().clone();
        let plain = device.clone().inner();
        let obs = rows_tensor(&batch.observations, obs_dim, &device);
        let actions = rows_tensor(&batch.actions, act_dim, &device);
        let next_obs = rows_tensor(&batch.next_observations, obs_dim, &device);
        let adam = sac.optimizer();
        let config = sac.config.clone();

        // Actor, then α (OfflineRL-Kit's order).
        let alpha = sac.temperature.alpha().inner();
        let noise = normal([b, act_dim], rng, &device);
        let (half, critic) = sac.policy_half();
        let policy = half.step(obs.clone(), noise, alpha, |o, a| critic.min_q(o, a));

        // Critics: deterministic backup y = r + γ(1 − d)·min Q̄(s', ã'), then the term.
        let next =
            (sac.actor.valid()).sample(next_obs.clone().inner(), normal([b, act_dim], rng, &plain));
        let next_value = sac
            .target_critic
            .min_q(next_obs.clone().inner(), next.action);
        let terminals = rows_tensor(&batch.terminals, 1, &plain);
        let y = rows_tensor(&batch.rewards, 1, &plain)
            + (terminals.neg() + 1.0) * next_value * config.gamma;
        let (_, qf1_loss, qf2_loss, qf1_values) = sac.critic_loss(obs.clone(), actions.clone(), y);
        let samples = self.draw_samples(act_dim, b, rng, &device);
        let (term1, term2) = self.terms(sac, obs, next_obs, actions, samples, data_rows);
        let total = qf1_loss.clone() + qf2_loss.clone() + term1 + term2;
        let grads = GradientsParams::from_grads(total.backward(), &sac.critic);
        sac.critic = adam.step_module(
            config.critic_lr,
            sac.critic.clone(),
            grads,
            &mut sac.adam.critic,
        );
        sac.target_critic = polyak_update(sac.target_critic.clone(), &sac.critic, config.tau);
        policy.losses(qf1_values, qf1_loss.into_scalar(), qf2_loss.into_scalar())
    }
}

/// log Σ_j exp(x_ij) per row, stable: `[rows, k]` → `[rows, 1]`.
fn log_sum_exp_rows(x: Tensor<2>) -> Tensor<2> {
    let max = x.clone().max_dim(1).detach();
    (x - max.clone()).exp().sum_dim(1).log() + max
}
