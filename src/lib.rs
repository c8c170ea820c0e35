//! nuno: neural stochastic differential equations with a distance-aware
//! uncertainty η for offline model-based RL (NUNO), as a library, an offline
//! trainer and a model server.
//!
//! One folder per concern:
//! - [`envs`]: the MuJoCo tasks (D4RL-v2 semantics), D4RL scores, the parallel evaluator;
//! - [`data`]: D4RL/NeoRL/Minari readers, the D4RL-layout writer, generators,
//!   the normaliser and samplers;
//! - [`sde`]: the neural SDE, its losses, fitting and truncation thresholds;
//! - [`ensemble`]: the Gaussian ensemble, MOPO's model, and its fit;
//! - [`agent`]: the method list, SAC on penalised, truncated model rollouts,
//!   behind the narrow batched `act` and `step` interfaces;
//! - [`planning`]: candidate action sequences scored in a model;
//! - [`experiment`]: grids of datasets × methods × seeds, each cell's result,
//!   the aggregate tables and the model analyses;
//! - [`nn`]: the MLP both use;
//! - [`infer`]: the fused CPU path that rollouts and the server evaluate trained networks with;
//! - [`artifact`]: everything nuno saves and its validated loading;
//! - [`server`]: the HTTP model server (axum), a thin layer over the rest;
//! - [`shared`]: what every concern may import and which imports none of them: the
//!   batch interfaces, the cancellation flag long work checks between steps, the
//!   atomic file writer.
//!
//! Dependencies run one way, down the list in docs/architecture.md (checked by
//! tests/layering.rs).

pub mod agent;
pub mod artifact;
pub mod data;
pub mod ensemble;
pub mod envs;
pub mod experiment;
pub mod export;
pub mod infer;
pub mod nn;
pub mod planning;
pub mod sde;
#[cfg(feature = "server")]
pub mod server;
pub mod shared;
