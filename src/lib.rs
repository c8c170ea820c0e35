//! nuno: neural stochastic differential equations with a distance-aware
//! uncertainty η for offline model-based RL (NUNO), as a library, an offline
//! trainer and a model server.
//!
//! One folder per concern:
//! - [`envs`]: the MuJoCo tasks (D4RL-v2 semantics), D4RL scores, the parallel evaluator;
//! - [`agent`]: policies behind the narrow batched `act` interface.

pub mod agent;
pub mod envs;
