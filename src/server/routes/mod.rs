//! The routes, one file per resource; request and response types live next to
//! their handlers and are re-exported for clients and tests.

mod act;
mod admin;
mod defaults;
mod evaluate;
mod health;
mod kserve;
mod kserve_binary;
mod models;
mod rollout;
mod step;

use axum::Router;
use axum::routing::{get, post};

pub use act::__path_act;
pub use act::{ActRequest, ActResponse};
pub use admin::__path_reload;
pub use evaluate::{
    __path_evaluate, __path_validate, EvaluateRequest, EvaluateResponse, ValidateRequest,
    ValidateResponse,
};
pub use health::{__path_healthz, __path_metrics, __path_readyz, Health, Readiness};
pub use kserve::{
    __path_infer, __path_live, __path_model_ready, __path_ready, __path_server_metadata,
    __path_v2_model_metadata, InferRequest, InferResponse, InferTensor, RequestedOutput,
    V2ModelMetadata, V2TensorMetadata,
};
pub use models::{__path_get_model, __path_list_models, ModelDetail, ModelList, ModelSummary};
pub use rollout::{__path_rollout, RolloutRequest, RolloutResponse, Trajectory};
pub use step::{__path_step, StepRequest, StepResponse};

use super::AppState;

/// Everything behind the optional bearer token.
pub(super) fn api_routes() -> Router<AppState> {
    Router::new()
        .route("/v1/models", get(models::list_models))
        .route("/v1/models/{id}", get(models::get_model))
        .route("/v1/models/{id}/step", post(step::step))
        .route("/v1/models/{id}/rollout", post(rollout::rollout))
        .route("/v1/models/{id}/act", post(act::act))
        .route("/v1/models/{id}/validate", post(evaluate::validate))
        .route("/v1/evaluate", post(evaluate::evaluate))
        .route("/v1/admin/reload", post(admin::reload))
        .route("/metrics", get(health::metrics))
        .route("/v2", get(kserve::server_metadata))
        .route("/v2/models/{id}", get(kserve::v2_model_metadata))
        .route("/v2/models/{id}/ready", get(kserve::model_ready))
        .route("/v2/models/{id}/infer", post(kserve::infer))
}

/// Health probes: never behind the token.
pub(super) fn health_routes() -> Router<AppState> {
    Router::new()
        .route("/healthz", get(health::healthz))
        .route("/readyz", get(health::readyz))
        .route("/v2/health/live", get(kserve::live))
        .route("/v2/health/ready", get(kserve::ready))
}
