//! The fused CPU kernels under the narrow batch interfaces
//! ([`crate::shared::BatchDynamics`], [`crate::shared::BatchPolicy`]): dense
//! layers, their gradients, vectorised activations and batch tiles, knowing
//! nothing of the models built from them (`sde::FusedSde`, `agent::FusedActor`,
//! `agent::FusedSac`).
//!
//! burn's CPU backend runs this model on one core at about a fifth of what
//! the layer shapes allow (BENCHMARKS.md). Rollouts and the server only ever
//! evaluate trained weights, so this path reads the same weights into plain
//! `f32` buffers and evaluates them with bias and activation fused into each
//! layer's pass, batch tiles sized for cache and spread over all cores
//! ([`tiles`]), and per-thread buffers reused across steps. [`TrainableMlp`]
//! adds the backward pass (and, for a loss on a scalar network's input
//! gradient, the reverse pass of its tangent pass), on which SAC's updates,
//! the ensemble's fit and the SDE's fit run; burn stays the path for the GPU
//! and the reference every fused gradient is tested against; [`Kernel`] picks
//! between them.

mod dense;
mod mlp_grad;
mod simd;
mod tiles;
mod vector_math;

pub use dense::{Dense, DenseMlp, GEMM_MIN_ROWS, MlpScratch, Rows};
pub use mlp_grad::{Layer, MlpTape, TrainableMlp};
pub use simd::{SimdLevel, detected_simd_level, set_simd_cap, simd_level};
pub use tiles::{MAX_TILE_ROWS, row_chunks, run_tiles, tile_rows, with_buffers};

/// Which code evaluates trained networks for rollouts and serving.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "server", derive(utoipa::ToSchema))]
#[serde(rename_all = "lowercase")]
pub enum Kernel {
    /// The fused CPU path of this module.
    #[default]
    Fused,
    /// burn's tensors on the model's device (the training code path).
    Burn,
}

impl std::fmt::Display for Kernel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Kernel::Fused => "fused",
            Kernel::Burn => "burn",
        })
    }
}

/// The names command lines take (`--kernel fused|burn`).
impl std::str::FromStr for Kernel {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim().to_ascii_lowercase().as_str() {
            "fused" => Ok(Kernel::Fused),
            "burn" => Ok(Kernel::Burn),
            other => Err(format!("unknown kernel `{other}` (expected fused or burn)")),
        }
    }
}
