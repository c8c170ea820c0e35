//! The fused CPU inference path under the narrow batch interfaces
//! ([`crate::sde::BatchDynamics`], [`crate::agent::BatchPolicy`]).
//!
//! burn's CPU backend runs this model on one core at about a fifth of what
//! the layer shapes allow (BENCHMARKS.md). Rollouts and the server only ever
//! evaluate trained weights, so this path reads the same weights into plain
//! `f32` buffers and evaluates them with bias and activation fused into each
//! layer's pass, batch tiles sized for cache and spread over all cores
//! ([`tiles`]), and per-thread buffers reused across steps. burn stays the
//! path for training and for the GPU; [`Kernel`] picks between them.

mod actor;
mod dense;
mod mlp_grad;
mod sde;
mod tiles;
mod vector_math;

pub use actor::FusedActor;
pub use dense::{Dense, DenseMlp, GEMM_MIN_ROWS, MlpScratch, Rows};
pub use mlp_grad::{Layer, MlpTape, ReluMlp};
pub use sde::FusedSde;
pub use tiles::MAX_TILE_ROWS;

use crate::agent::{ActorPolicy, BatchPolicy};
use crate::sde::{BatchDynamics, NeuralSde};

/// Which code evaluates trained networks for rollouts and serving.
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    Default,
    serde::Serialize,
    serde::Deserialize,
    clap::ValueEnum,
    utoipa::ToSchema,
)]
#[serde(rename_all = "lowercase")]
pub enum Kernel {
    /// The fused CPU path of this module.
    #[default]
    Fused,
    /// burn's tensors on the model's device (the training code path).
    Burn,
}

impl Kernel {
    /// `model` behind the batch interface, evaluated by this kernel.
    pub fn dynamics<'a>(self, model: &'a NeuralSde) -> Box<dyn BatchDynamics + 'a> {
        match self {
            Kernel::Fused => Box::new(FusedSde::new(model)),
            Kernel::Burn => Box::new(model),
        }
    }

    /// `policy` behind the batch interface, evaluated by this kernel.
    pub fn policy(self, policy: ActorPolicy) -> Box<dyn BatchPolicy> {
        match self {
            Kernel::Fused => Box::new(FusedActor::new(&policy)),
            Kernel::Burn => Box::new(policy),
        }
    }
}
