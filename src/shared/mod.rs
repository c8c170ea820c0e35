//! What every concern may import, and which imports none of them: the batch
//! interfaces, the cancellation flag, the atomic file writer, the names of
//! field-less enums, the derived seeds, the metrics table and the mean ± std of reports.

pub mod atomic;
pub mod batch;
pub mod cancel;
mod metrics_table;
mod named_enum;
pub mod seed;
mod stats;

pub use atomic::write_atomically;
pub use batch::{
    BatchDynamics, BatchPolicy, BatchShape, LoggedActions, ModelStep, TransitionBatch, act_batch,
    euler_maruyama, scaled_noise, step_batch,
};
pub use cancel::{Cancel, CancelOnDrop, Cancelled};
pub use metrics_table::{Metric, MetricsTable};
pub(crate) use named_enum::named_enum;
pub use seed::{SeedStream, derive_seed};
pub use stats::{mean_std_population, mean_std_sample};
