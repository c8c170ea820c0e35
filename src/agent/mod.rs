//! Policies: the batched `act` interface that evaluation and model rollouts call,
//! and the policies behind it.

mod policy;

pub use policy::{BatchPolicy, RandomPolicy};
