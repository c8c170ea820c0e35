//! SAC's actor on the fused CPU path: the same actions as [`ActorPolicy`] for
//! the same generator, over row tiles in parallel.

use std::cell::RefCell;
use std::sync::Arc;

use rand::RngCore;

use super::actor::tanh_gaussian_log_density;
use super::{ActionMode, ActorConfig, ActorPolicy, action_noise};
use crate::infer::{
    DenseMlp, Kernel, MlpScratch, Rows, row_chunks, run_tiles, tile_rows, with_buffers,
};
use crate::shared::{BatchPolicy, LoggedActions, act_batch};

/// A trained actor's weights laid out for [`BatchPolicy::act`] on the CPU.
#[derive(Debug, Clone)]
pub struct FusedActor {
    /// Shared, so that the same weights in another [`ActionMode`] cost nothing.
    net: Arc<DenseMlp>,
    config: ActorConfig,
    mode: ActionMode,
    /// Half-width and centre of the action box.
    half: Vec<f32>,
    center: Vec<f32>,
    /// Σ log half, the action box's term of log π(a|s).
    log_half_sum: f32,
}

/// One tile's observations, noise (sampled mode) and the actions (and, when
/// asked for, log-probabilities) it fills.
struct Tile<'a> {
    observations: &'a [f32],
    noise: &'a [f32],
    actions: &'a mut [f32],
    log_probs: &'a mut [f32],
}

thread_local! {
    /// The network's output `[rows, 2·act_dim]` and hidden activations of one tile.
    static SCRATCH: RefCell<(Vec<f32>, MlpScratch)> = RefCell::default();
}

impl FusedActor {
    /// The same policy as `policy`, its weights copied out of burn.
    pub fn new(policy: &ActorPolicy) -> Self {
        let (half, center) = policy.actor.config.box_half_center();
        Self {
            net: Arc::new(DenseMlp::from_burn(&policy.actor.net)),
            config: policy.actor.config.clone(),
            mode: policy.mode,
            log_half_sum: half.iter().map(|h| h.ln()).sum(),
            half,
            center,
        }
    }

    /// The same weights, choosing actions by `mode`.
    pub fn with_mode(&self, mode: ActionMode) -> Self {
        Self {
            mode,
            ..self.clone()
        }
    }

    fn act_tile(&self, tile: Tile, (out, mlp): &mut (Vec<f32>, MlpScratch)) {
        let a = self.config.act_dim;
        let rows = tile.actions.len() / a;
        out.resize(rows * 2 * a, 0.0);
        self.net.forward(
            Rows::dense(tile.observations, self.config.obs_dim),
            out,
            mlp,
        );
        for (r, (action, mean_log_std)) in tile
            .actions
            .chunks_exact_mut(a)
            .zip(out.chunks_exact(2 * a))
            .enumerate()
        {
            let (mean, log_std) = mean_log_std.split_at(a);
            let mut log_prob = -self.log_half_sum;
            for d in 0..a {
                let u = match self.mode {
                    ActionMode::Deterministic => mean[d],
                    ActionMode::Sampled => {
                        let log_std =
                            log_std[d].clamp(self.config.log_std_min, self.config.log_std_max);
                        let eps = tile.noise[r * a + d];
                        let u = mean[d] + log_std.exp() * eps;
                        log_prob += tanh_gaussian_log_density(eps, log_std, u);
                        u
                    }
                };
                action[d] = u.tanh() * self.half[d] + self.center[d];
            }
            if let Some(slot) = tile.log_probs.get_mut(r) {
                *slot = log_prob;
            }
        }
    }

    /// Actions for `observations`, and log π(a|s) per row when `logged` (in
    /// sampled mode; a deterministic actor has no density).
    fn act_rows(&self, observations: &[f32], rng: &mut dyn RngCore, logged: bool) -> LoggedActions {
        let batch = act_batch(self, observations);
        let (obs_dim, act_dim) = (self.obs_dim(), self.act_dim());
        let sampled = self.mode == ActionMode::Sampled;
        let noise = if sampled {
            action_noise(batch * act_dim, rng)
        } else {
            Vec::new()
        };
        let mut actions = vec![0.0; batch * act_dim];
        let mut log_probs = vec![0.0; if logged && sampled { batch } else { 0 }];
        let rows = tile_rows(batch);
        let noise_rows = if noise.is_empty() { 0 } else { rows * act_dim };
        let mut log_prob_chunks = row_chunks(&mut log_probs, rows, 1);
        let tiles = observations
            .chunks(rows * obs_dim)
            .zip(row_chunks(&mut actions, rows, act_dim))
            .enumerate()
            .map(|(i, (observations, actions))| Tile {
                observations,
                noise: noise.get(i * noise_rows..).unwrap_or_default(),
                actions,
                log_probs: log_prob_chunks.next().unwrap_or_default(),
            })
            .collect();
        run_tiles(tiles, |tile| {
            with_buffers(&SCRATCH, |s| self.act_tile(tile, s))
        });
        LoggedActions {
            actions,
            log_probs: (logged && sampled).then_some(log_probs),
        }
    }
}

impl BatchPolicy for FusedActor {
    fn obs_dim(&self) -> usize {
        self.config.obs_dim
    }

    fn act_dim(&self) -> usize {
        self.config.act_dim
    }

    fn act(&self, observations: &[f32], rng: &mut dyn RngCore) -> Vec<f32> {
        self.act_rows(observations, rng, false).actions
    }

    fn act_logged(&self, observations: &[f32], rng: &mut dyn RngCore) -> LoggedActions {
        self.act_rows(observations, rng, true)
    }
}

impl Kernel {
    /// `policy` behind the batch interface, evaluated by this kernel.
    pub fn policy(self, policy: ActorPolicy) -> Box<dyn BatchPolicy> {
        match self {
            Kernel::Fused => Box::new(FusedActor::new(&policy)),
            Kernel::Burn => Box::new(policy),
        }
    }
}
