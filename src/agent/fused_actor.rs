//! SAC's actor on the fused CPU path: the same actions as [`ActorPolicy`] for
//! the same generator, over row tiles in parallel.

use std::cell::RefCell;
use std::sync::Arc;

use rand::RngCore;

use super::{ActionMode, ActorConfig, ActorPolicy, action_noise};
use crate::infer::{
    DenseMlp, Kernel, MlpScratch, Rows, row_chunks, run_tiles, tile_rows, with_buffers,
};
use crate::shared::{BatchPolicy, act_batch};

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
}

/// One tile's observations, noise (sampled mode) and the actions it fills.
struct Tile<'a> {
    observations: &'a [f32],
    noise: &'a [f32],
    actions: &'a mut [f32],
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
            for d in 0..a {
                let u = match self.mode {
                    ActionMode::Deterministic => mean[d],
                    ActionMode::Sampled => {
                        let log_std =
                            log_std[d].clamp(self.config.log_std_min, self.config.log_std_max);
                        mean[d] + log_std.exp() * tile.noise[r * a + d]
                    }
                };
                action[d] = u.tanh() * self.half[d] + self.center[d];
            }
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
        let batch = act_batch(self, observations);
        let (obs_dim, act_dim) = (self.obs_dim(), self.act_dim());
        let noise = match self.mode {
            ActionMode::Deterministic => Vec::new(),
            ActionMode::Sampled => action_noise(batch * act_dim, rng),
        };
        let mut actions = vec![0.0; batch * act_dim];
        let rows = tile_rows(batch);
        let noise_rows = if noise.is_empty() { 0 } else { rows * act_dim };
        let tiles = observations
            .chunks(rows * obs_dim)
            .zip(row_chunks(&mut actions, rows, act_dim))
            .enumerate()
            .map(|(i, (observations, actions))| Tile {
                observations,
                noise: noise.get(i * noise_rows..).unwrap_or_default(),
                actions,
            })
            .collect();
        run_tiles(tiles, |tile| {
            with_buffers(&SCRATCH, |s| self.act_tile(tile, s))
        });
        actions
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
