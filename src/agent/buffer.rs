//! A ring of the most recent transitions. As policy optimisation's model
//! buffer its capacity is `rollout_batch · h · particles · retain_epochs`, so
//! it holds the last `retain_epochs` rollouts (more when truncation kept
//! rollouts short), as in MOPO's `model_retain_epochs`; as online SAC's replay
//! buffer it holds the run's steps.

use rand::Rng;

use crate::shared::TransitionBatch;

/// A fixed-capacity ring of transitions `(s, a, r, s', d)`.
#[derive(Debug, Clone, PartialEq)]
pub struct ReplayBuffer {
    pub obs_dim: usize,
    pub act_dim: usize,
    pub capacity: usize,
    /// Rows filled so far (≤ capacity).
    pub len: usize,
    /// Row the next transition overwrites.
    pub next: usize,
    /// Row-major columns, `capacity` rows each once full.
    pub data: TransitionBatch,
}

impl ReplayBuffer {
    pub fn new(capacity: usize, obs_dim: usize, act_dim: usize) -> Self {
        Self {
            obs_dim,
            act_dim,
            capacity,
            len: 0,
            next: 0,
            data: TransitionBatch::with_capacity(capacity.min(1 << 20), obs_dim, act_dim),
        }
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Adds `batch`, overwriting the oldest rows once full.
    pub fn push(&mut self, batch: &TransitionBatch) {
        let (o, a) = (self.obs_dim, self.act_dim);
        for i in 0..batch.len() {
            self.push_row(
                &batch.observations[i * o..(i + 1) * o],
                &batch.actions[i * a..(i + 1) * a],
                batch.rewards[i],
                &batch.next_observations[i * o..(i + 1) * o],
                batch.terminals[i],
            );
        }
    }

    /// Adds one transition `(s, a, r, s', d)`, overwriting the oldest once full.
    pub fn push_row(&mut self, obs: &[f32], action: &[f32], reward: f32, next: &[f32], done: f32) {
        let (o, a) = (self.obs_dim, self.act_dim);
        let d = &mut self.data;
        if self.len < self.capacity {
            d.observations.extend_from_slice(obs);
            d.actions.extend_from_slice(action);
            d.rewards.push(reward);
            d.next_observations.extend_from_slice(next);
            d.terminals.push(done);
            self.len += 1;
        } else {
            let r = self.next;
            d.observations[r * o..(r + 1) * o].copy_from_slice(obs);
            d.actions[r * a..(r + 1) * a].copy_from_slice(action);
            d.rewards[r] = reward;
            d.next_observations[r * o..(r + 1) * o].copy_from_slice(next);
            d.terminals[r] = done;
        }
        self.next = (self.next + 1) % self.capacity.max(1);
    }

    /// `n` transitions drawn uniformly with replacement (empty when the buffer is).
    pub fn sample(&self, n: usize, rng: &mut impl Rng) -> TransitionBatch {
        let (o, a) = (self.obs_dim, self.act_dim);
        let mut out = TransitionBatch::with_capacity(n, o, a);
        if self.is_empty() {
            return out;
        }
        let d = &self.data;
        for _ in 0..n {
            let r = rng.random_range(0..self.len);
            out.observations
                .extend_from_slice(&d.observations[r * o..(r + 1) * o]);
            out.actions
                .extend_from_slice(&d.actions[r * a..(r + 1) * a]);
            out.rewards.push(d.rewards[r]);
            out.next_observations
                .extend_from_slice(&d.next_observations[r * o..(r + 1) * o]);
            out.terminals.push(d.terminals[r]);
        }
        out
    }
}
