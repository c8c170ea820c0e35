//! The routes, one file per resource; request and response types live next to
//! their handlers and are re-exported for clients and tests.

mod act;
mod admin;
mod evaluate;
mod fields;
mod health;
pub(super) mod kserve;
pub(super) mod kserve_binary;
mod models;
mod plan;
mod rollout;
mod score;
mod scoring;
mod step;

pub use act::{ActRequest, ActResponse};
pub use evaluate::{EvaluateRequest, EvaluateResponse, ValidateRequest, ValidateResponse};
pub use health::{Health, Readiness};
pub(super) use kserve::OUTPUTS;
pub use kserve::{
    InferInput, InferRequest, InferResponse, InferTensor, InputData, RequestedOutput,
    V2ModelMetadata, V2TensorMetadata,
};
pub use models::{ModelDetail, ModelList, ModelSummary};
pub use plan::{PlanRequest, PlanResponse};
pub use rollout::{RolloutRequest, RolloutResponse, Trajectory};
pub use score::{ScoreRequest, ScoreResponse};
pub use scoring::{CostRequest, CostTermRequest, ObservationRef};
pub use step::{StepRequest, StepResponse};

use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use super::AppState;

/// Everything behind the optional bearer token. Each route's path and method
/// come from its handler's `#[utoipa::path]`, so the spec cannot drift from
/// what is served.
pub(super) fn api_routes() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(models::list_models))
        .routes(routes!(models::get_model))
        .routes(routes!(step::step))
        .routes(routes!(rollout::rollout))
        .routes(routes!(score::score))
        .routes(routes!(plan::plan_route))
        .routes(routes!(act::act))
        .routes(routes!(evaluate::validate))
        .routes(routes!(evaluate::evaluate))
        .routes(routes!(admin::reload))
        .routes(routes!(health::metrics))
        .routes(routes!(kserve::server_metadata))
        .routes(routes!(kserve::v2_model_metadata))
        .routes(routes!(kserve::model_ready))
        .routes(routes!(kserve::infer))
}

/// Health probes: never behind the token.
pub(super) fn health_routes() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(health::healthz))
        .routes(routes!(health::readyz))
        .routes(routes!(kserve::live))
        .routes(routes!(kserve::ready))
}
