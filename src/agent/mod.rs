//! Policies: the batched `act` interface that evaluation and model rollouts call,
//! and the policies behind it.

mod policy;
mod random_network;

pub use policy::{BatchPolicy, RandomPolicy};
pub use random_network::RandomNetworkPolicy;
