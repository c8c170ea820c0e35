//! EDAC's update ([`Edac::update`]) on the fused kernel: the N critics side by
//! side on the cores, and the diversity term's gradient in two passes —
//! each critic's action gradient gⱼ = ∇ₐQⱼ(s, a) (a backward pass from 1),
//! then, with the normalised ĝⱼ = gⱼ/(‖gⱼ‖ + ε) summed over the critics,
//!
//! ```text
//! ∂(η·ES)/∂ĝⱼ = 2η/((N − 1)·B) · (Σₖ ĝₖ − ĝⱼ)                      (u)
//! ∂(η·ES)/∂gⱼ = u/(‖gⱼ‖ + ε) − gⱼ·(gⱼ·u)/(‖gⱼ‖·(‖gⱼ‖ + ε)²)
//! ```
//!
//! which [`TrainableMlp::backward_through_input_gradient`] turns into each
//! critic's parameter gradient together with its (Qⱼ − y)²'s.

use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use super::{Agent, FusedSac, concat_rows, critic_pair};
use crate::agent::edac::{Edac, GRADIENT_NORM_EPSILON};
use crate::agent::sac::SacLosses;
use crate::infer::TrainableMlp;
use crate::nn::{Adam, fill_standard_normal};
use crate::shared::TransitionBatch;

impl FusedSac {
    /// The state of `edac` (actor, N critics, temperature, Adam) on host buffers.
    pub fn from_edac(edac: &Edac) -> Self {
        let critics = (edac
            .critics
            .members
            .iter()
            .zip(&edac.target_critics.members))
        .enumerate()
        .map(|(j, (net, target))| critic_pair(&format!("members.{j}"), net, target))
        .collect();
        let sac = &edac.config.sac;
        let agent = Agent {
            actor: &edac.actor,
            config: sac,
            target_entropy: edac.target_entropy,
            temperature: &edac.temperature,
            adam: (Adam::new(sac.adam_epsilon.unwrap_or(1e-8)), &edac.adam),
        };
        Self::from_parts(agent, critics)
    }

    /// Writes every network, the temperature and the Adam state into `edac`.
    pub fn write_to_edac(&self, edac: &mut Edac) {
        edac.actor.net = self.actor.write_to(edac.actor.net.clone());
        let pairs = (edac.critics.members.iter_mut()).zip(&mut edac.target_critics.members);
        for (c, (net, target)) in self.critics.iter().zip(pairs) {
            *net = c.net.write_to(net.clone());
            *target = c.target.write_to(target.clone());
        }
        edac.temperature = edac.temperature.with_log_alpha(self.log_alpha);
        edac.adam = self.state.clone();
    }

    /// [`Edac::update`] on host buffers, η the diversity term's weight: the
    /// actor, α, then the critics, then the targets; ε drawn from `rng` in its order.
    pub fn update_edac(
        &mut self,
        eta: f32,
        batch: &TransitionBatch,
        rng: &mut ChaCha8Rng,
    ) -> SacLosses {
        // On the pool, as `update` (its comment says why).
        rayon::scope(|_| self.edac_on_pool(eta, batch, rng))
    }

    fn edac_on_pool(
        &mut self,
        eta: f32,
        batch: &TransitionBatch,
        rng: &mut ChaCha8Rng,
    ) -> SacLosses {
        let b = batch.rewards.len();
        // EDAC reads α clamped to [0, 1]; its loss steps log α unclamped.
        let alpha = self.log_alpha.exp().clamp(0.0, 1.0);
        let policy = self.policy_steps(&batch.observations, alpha, rng);

        fill_standard_normal(&mut self.work.noise, b * self.act_dim, rng);
        let stepped_alpha = self.log_alpha.exp().clamp(0.0, 1.0);
        self.critic_target(batch, stepped_alpha, None);
        let critic = self.diverse_critic_gradients(eta, batch);
        self.step_critics();
        self.update_targets();
        policy.with(alpha, critic)
    }

    /// ∂(Σⱼ mean (Qⱼ − y)² + η·ES)/∂θⱼ of every critic into its `grads` at the
    /// batch's (s, a); returns the critics' squared-error losses.
    fn diverse_critic_gradients(&mut self, eta: f32, batch: &TransitionBatch) -> SacLosses {
        let (o, a) = (self.obs_dim, self.act_dim);
        let b = batch.rewards.len();
        let w = &mut self.work;
        concat_rows(
            &batch.observations,
            &batch.actions,
            o,
            a,
            &mut w.critic_input,
        );
        let (input, y) = (&w.critic_input, &w.y);

        // Qⱼ and ∇ₓQⱼ, each critic on its share of the cores.
        let ones = vec![1.0; b];
        (self.critics.par_iter_mut()).for_each(|c| {
            c.net.forward(input, b, &mut c.tape);
            (c.net).backward(&mut c.tape, &ones, None, Some(&mut c.grad_input));
        });
        let mut sum = vec![0.0f32; b * a];
        for c in &self.critics {
            for (r, total) in sum.chunks_exact_mut(a).enumerate() {
                let (g, norm) = action_gradient(&c.grad_input, r, (o, a));
                total.iter_mut().zip(g).for_each(|(t, g)| *t += g / norm);
            }
        }

        // Both losses' gradients in one reverse pass per critic.
        let weight = 2.0 * eta / ((self.critics.len().max(2) - 1) * b) as f32;
        let losses: Vec<f32> = (self.critics.par_iter_mut())
            .map(|c| {
                c.grad_q.clear();
                let mut squares = 0.0;
                for (q, y) in c.tape.output.iter().zip(y) {
                    squares += (q - y) * (q - y);
                    c.grad_q.push(2.0 * (q - y) / b as f32);
                }
                normalisation_gradient(&c.grad_input, &sum, weight, (o, a), &mut c.upstream);
                let net: &TrainableMlp = &c.net;
                net.backward_through_input_gradient(
                    &mut c.tape,
                    &c.grad_q,
                    &c.upstream,
                    &mut c.grads,
                );
                squares / b as f32
            })
            .collect();
        self.critic_losses(&losses, b)
    }
}

/// Row `r`'s action part gⱼ of an input gradient `[rows, o + a]`, and ‖gⱼ‖ + ε.
fn action_gradient(grad_input: &[f32], r: usize, (o, a): (usize, usize)) -> (&[f32], f32) {
    let g = &grad_input[r * (o + a) + o..(r + 1) * (o + a)];
    let norm = g.iter().map(|x| x * x).sum::<f32>().sqrt() + GRADIENT_NORM_EPSILON;
    (g, norm)
}

/// ∂(η·ES)/∂∇ₓQⱼ for every row (zero on the state's part) into `out`, from
/// this critic's input gradient, Σₖ ĝₖ (`sum`, `[rows, a]`) and 2η/((N − 1)·B).
fn normalisation_gradient(
    grad_input: &[f32],
    sum: &[f32],
    weight: f32,
    (o, a): (usize, usize),
    out: &mut Vec<f32>,
) {
    let rows = sum.len() / a;
    out.clear();
    out.resize(rows * (o + a), 0.0);
    for r in 0..rows {
        let (g, denominator) = action_gradient(grad_input, r, (o, a));
        let norm = denominator - GRADIENT_NORM_EPSILON;
        // u = ∂(η·ES)/∂ĝⱼ first, then through the normalisation, in place.
        let row = &mut out[r * (o + a) + o..(r + 1) * (o + a)];
        for (k, u) in row.iter_mut().enumerate() {
            *u = weight * (sum[r * a + k] - g[k] / denominator);
        }
        let g_dot_u: f32 = g.iter().zip(row.iter()).map(|(g, u)| g * u).sum();
        let radial = if norm > 0.0 {
            g_dot_u / (norm * denominator * denominator)
        } else {
            0.0
        };
        for (u, g) in row.iter_mut().zip(g) {
            *u = *u / denominator - g * radial;
        }
    }
}
