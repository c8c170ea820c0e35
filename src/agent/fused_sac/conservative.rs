//! CQL's and COMBO's update ([`ConservativeTerm::update`]) on the fused
//! kernel. Each critic sees one input of `B + 3·B·N` rows — the batch's
//! (s, a), then s repeated N times with ã ~ π(·|s), with ã' ~ π(·|s') and with
//! uniform actions — and one backward pass takes both losses' gradients:
//!
//! ```text
//! ∂/∂Q_i(s, a)   = 2(Q_i − y)/B − β/B_data   (the data term on the first B_data rows)
//! ∂/∂X_row,j     = β · softmax_j(X_row / T) / (B·N)   (T·LSE_T's gradient, X = Q_i − log π)
//! ```

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use super::{FusedSac, concat_rows, sample};
use crate::agent::cql::ConservativeTerm;
use crate::agent::sac::{CriticBackup, SacLosses};
use crate::nn::fill_standard_normal;
use crate::shared::TransitionBatch;

/// CQL's backup leaves out the entropy term (OfflineRL-Kit's `deterministic_backup`).
const DETERMINISTIC: CriticBackup = CriticBackup {
    deterministic: true,
    floor: None,
};

impl FusedSac {
    /// [`ConservativeTerm::update`] on host buffers: the actor, α, then the
    /// critics with the term (the first `data_rows` rows of `batch` real),
    /// then the targets; ε, the uniform actions and the sampled actions drawn
    /// from `rng` in its order.
    pub fn update_conservative(
        &mut self,
        term: &ConservativeTerm,
        batch: &TransitionBatch,
        data_rows: usize,
        rng: &mut ChaCha8Rng,
    ) -> SacLosses {
        // On the pool, as `update` (its comment says why).
        rayon::scope(|_| self.conservative_on_pool(term, batch, data_rows, rng))
    }

    fn conservative_on_pool(
        &mut self,
        term: &ConservativeTerm,
        batch: &TransitionBatch,
        data_rows: usize,
        rng: &mut ChaCha8Rng,
    ) -> SacLosses {
        let b = batch.rewards.len();
        let alpha = self.log_alpha.exp();
        // Actor, then α (OfflineRL-Kit's order), through the critics before their step.
        let policy = self.policy_steps(&batch.observations, alpha, rng);

        fill_standard_normal(&mut self.work.noise, b * self.act_dim, rng);
        self.critic_target(batch, alpha, Some(DETERMINISTIC));
        self.draw_term_samples(term, b, rng);
        let critic = self.conservative_critic_gradients(term, batch, data_rows);
        self.step_critics();
        self.update_targets();
        policy.with(alpha, critic)
    }

    /// [`ConservativeTerm::draw_samples`]'s draws, in its order: the uniform
    /// actions into `work.uniform`, then ε at s and at s' into `work.noise`.
    fn draw_term_samples(&mut self, term: &ConservativeTerm, b: usize, rng: &mut ChaCha8Rng) {
        let n = b * term.num_repeat_actions * self.act_dim;
        let w = &mut self.work;
        w.uniform.clear();
        w.uniform
            .extend((0..n).map(|_| rng.random_range(-1.0f32..1.0)));
        fill_standard_normal(&mut w.noise, 2 * n, rng);
    }

    /// ∂(L_Q + term)/∂θ of every critic into its `grads`, the actions
    /// sampled from the (stepped) actor; returns the critics' squared-error losses.
    fn conservative_critic_gradients(
        &mut self,
        term: &ConservativeTerm,
        batch: &TransitionBatch,
        data_rows: usize,
    ) -> SacLosses {
        let (o, a) = (self.obs_dim, self.act_dim);
        let (b, repeat) = (batch.rewards.len(), term.num_repeat_actions);
        let bn = b * repeat;
        let w = &mut self.work;
        w.repeated.clear();
        for states in [&batch.observations, &batch.next_observations] {
            for row in states.chunks_exact(o) {
                (0..repeat).for_each(|_| w.repeated.extend_from_slice(row));
            }
        }
        self.actor.forward(&w.repeated, 2 * bn, &mut w.actor_tape);
        let action_box = (&self.half[..], &self.center[..], self.log_half_sum);
        sample(
            &w.actor_tape.output,
            &w.noise,
            action_box,
            self.log_std,
            &mut w.sample,
        );

        // [s, a] of the batch, then s repeated with ã, ã' and the uniform actions.
        concat_rows(
            &batch.observations,
            &batch.actions,
            o,
            a,
            &mut w.critic_input,
        );
        let at_state = &w.repeated[..bn * o];
        let (from_state, from_next) = w.sample.action.split_at(bn * a);
        for actions in [from_state, from_next, &w.uniform[..]] {
            for (s, act) in at_state.chunks_exact(o).zip(actions.chunks_exact(a)) {
                w.critic_input.extend_from_slice(s);
                w.critic_input.extend_from_slice(act);
            }
        }
        let rows = b + 3 * bn;
        let shape = TermShape {
            batch: b,
            data_rows,
            uniform_log_density: a as f32 * 0.5f32.ln(),
        };
        let (input, y, log_prob) = (&w.critic_input, &w.y, &w.sample.log_prob);
        let losses: Vec<f32> = (self.critics.par_iter_mut())
            .map(|c| {
                c.net.forward(input, rows, &mut c.tape);
                let squares =
                    term.output_gradient(&shape, &c.tape.output, y, log_prob, &mut c.grad_q);
                c.net
                    .backward(&mut c.tape, &c.grad_q, Some(&mut c.grads), None);
                squares
            })
            .collect();
        self.critic_losses(&losses, b)
    }
}

/// How a critic's `B + 3·B·N` outputs are laid out.
struct TermShape {
    batch: usize,
    data_rows: usize,
    /// log 0.5^|A|, the uniform actions' log density.
    uniform_log_density: f32,
}

impl ConservativeTerm {
    /// ∂(L_Q + term)/∂Q for every row of one critic's `outputs` into `grad`
    /// (the module doc's two lines), `log_prob` the sampled actions' (ã's,
    /// then ã''s); returns the mean squared error on the batch.
    fn output_gradient(
        &self,
        shape: &TermShape,
        outputs: &[f32],
        y: &[f32],
        log_prob: &[f32],
        grad: &mut Vec<f32>,
    ) -> f32 {
        let b = shape.batch;
        let bn = b * self.num_repeat_actions;
        let (beta, temperature) = (self.cql_weight as f32, self.temperature as f32);
        let data_weight = beta / shape.data_rows as f32;
        grad.clear();
        let mut squares = 0.0;
        for (r, (q, y)) in outputs[..b].iter().zip(y).enumerate() {
            squares += (q - y) * (q - y);
            let data = if r < shape.data_rows {
                data_weight
            } else {
                0.0
            };
            grad.push(2.0 * (q - y) / b as f32 - data);
        }
        grad.resize(b + 3 * bn, 0.0);
        let (pi, rest) = outputs[b..].split_at(bn);
        let (next, random) = rest.split_at(bn);
        let per_row = beta / bn as f32;
        for i in 0..bn {
            let x = [
                pi[i] - log_prob[i],
                next[i] - log_prob[bn + i],
                random[i] - shape.uniform_log_density,
            ];
            let max = x.iter().fold(f32::NEG_INFINITY, |m, &v| m.max(v));
            let e = x.map(|v| ((v - max) / temperature).exp());
            let sum: f32 = e.iter().sum();
            for (j, e) in e.iter().enumerate() {
                grad[b + j * bn + i] = per_row * e / sum;
            }
        }
        squares / b as f32
    }
}
