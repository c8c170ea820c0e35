//! The OpenAPI 3.1 document, generated from the handlers' annotations and
//! committed as `openapi/openapi.json` (a test fails when it is stale), plus
//! the interactive docs at `/docs` and the spec at `/openapi.json`.

use axum::Json;
use axum::Router;
use axum::routing::get;
use utoipa::openapi::security::{HttpAuthScheme, HttpBuilder, SecurityScheme};
use utoipa::{Modify, OpenApi};
use utoipa_scalar::{Scalar, Servable};

use super::AppState;
use super::routes::*;

/// The bearer token (when the server runs with one).
struct BearerAuth;

impl Modify for BearerAuth {
    fn modify(&self, openapi: &mut utoipa::openapi::OpenApi) {
        if let Some(components) = openapi.components.as_mut() {
            components.add_security_scheme(
                "bearer",
                SecurityScheme::Http(HttpBuilder::new().scheme(HttpAuthScheme::Bearer).build()),
            );
        }
    }
}

#[derive(OpenApi)]
#[openapi(
    info(
        title = "nuno model server",
        description = "Batched queries to neural-SDE dynamics with distance-aware uncertainty η (NUNO): \
            next-state samples, η, penalised rewards, truncation, policy actions, and MuJoCo-backed evaluation. \
            Every error is `{ \"error\": { \"code\", \"message\" } }` (KServe v2 routes: `{ \"error\": \"...\" }`). \
            With `--token`, every route except the health probes needs `Authorization: Bearer <token>`.",
        license(name = "MIT OR Apache-2.0")
    ),
    paths(
        list_models, get_model, step, rollout, act, evaluate, validate, reload,
        healthz, readyz, metrics, live, ready, server_metadata, v2_model_metadata,
        model_ready, infer
    ),
    components(schemas(crate::server::ErrorBody, crate::server::ErrorDetail)),
    modifiers(&BearerAuth),
    // The token is optional: a server started without `--token` needs none.
    security((), ("bearer" = [])),
    tags(
        (name = "models", description = "Model queries"),
        (name = "evaluation", description = "Runs in the real MuJoCo task"),
        (name = "kserve-v2", description = "KServe Open Inference Protocol v2"),
        (name = "admin", description = "Reloading models"),
        (name = "health", description = "Probes and metrics"),
    )
)]
pub struct ApiDoc;

/// The spec as pretty JSON, as committed in `openapi/openapi.json`.
pub fn openapi_json() -> String {
    ApiDoc::openapi()
        .to_pretty_json()
        .unwrap_or_else(|e| format!("{{\"error\": \"{e}\"}}"))
        + "\n"
}

pub(super) fn docs_routes() -> Router<AppState> {
    Router::new()
        .route("/openapi.json", get(|| async { Json(ApiDoc::openapi()) }))
        .merge(Scalar::with_url("/docs", ApiDoc::openapi()))
}
