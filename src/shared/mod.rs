//! What every concern may import, and which imports none of them: the batch
//! interfaces, the cancellation flag, the atomic file writer and the names of
//! field-less enums.

pub mod atomic;
pub mod batch;
pub mod cancel;
mod named_enum;

pub use atomic::write_atomically;
pub use batch::{
    BatchDynamics, BatchPolicy, BatchShape, LoggedActions, ModelStep, TransitionBatch, act_batch,
    euler_maruyama, scaled_noise, step_batch,
};
pub use cancel::{Cancel, CancelOnDrop, Cancelled};
pub(crate) use named_enum::named_enum;
