//! Every error the API returns, mapped in one place to a status code and a
//! JSON body: `{ "error": { "code", "message" } }`, or the KServe Open
//! Inference Protocol's `{ "error": "<message>" }` on its `/v2` routes.

use axum::Json;
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

/// What went wrong with a request.
#[derive(Debug, thiserror::Error)]
pub enum ApiError {
    #[error("model `{0}` is not loaded (GET /v1/models lists the loaded ones)")]
    UnknownModel(String),
    #[error("model `{0}` has no policy (train one with `nuno-trainer fit-policy`)")]
    NoPolicy(String),
    #[error(
        "model `{model}` is of `{system}`, a system described in a file without a [mujoco] table: there is no simulator to run it in"
    )]
    NoSimulator { model: String, system: String },
    #[error("{0}")]
    UnknownSession(String),
    #[error("no route {0} (the API is listed at /docs and /openapi.json)")]
    NoRoute(String),
    #[error("malformed request body: {0}")]
    Malformed(String),
    #[error("{0}")]
    Invalid(String),
    #[error("{0}")]
    OverLimit(String),
    #[error("request body larger than the limit of {0} bytes")]
    TooLarge(usize),
    #[error("unsupported content type `{given}` (this route takes {accepted})")]
    UnsupportedMediaType {
        given: String,
        accepted: &'static str,
    },
    #[error("missing or wrong bearer token")]
    Unauthorized,
    #[error("the request did not finish within {0} s")]
    Timeout(u64),
    #[error("the computation was cancelled: its request timed out or its client hung up")]
    Cancelled,
    #[error("internal error: {0}")]
    Internal(String),
}

impl ApiError {
    /// The HTTP status and the stable machine-readable code.
    pub fn status_code(&self) -> (StatusCode, &'static str) {
        match self {
            ApiError::UnknownModel(_) => (StatusCode::NOT_FOUND, "model_not_found"),
            ApiError::NoRoute(_) => (StatusCode::NOT_FOUND, "route_not_found"),
            ApiError::UnknownSession(_) => (StatusCode::NOT_FOUND, "session_not_found"),
            ApiError::NoPolicy(_) => (StatusCode::CONFLICT, "no_policy"),
            ApiError::NoSimulator { .. } => (StatusCode::CONFLICT, "no_simulator"),
            ApiError::Malformed(_) => (StatusCode::BAD_REQUEST, "malformed_body"),
            ApiError::Invalid(_) => (StatusCode::UNPROCESSABLE_ENTITY, "invalid_request"),
            ApiError::OverLimit(_) => (StatusCode::UNPROCESSABLE_ENTITY, "over_limit"),
            ApiError::TooLarge(_) => (StatusCode::PAYLOAD_TOO_LARGE, "body_too_large"),
            ApiError::UnsupportedMediaType { .. } => {
                (StatusCode::UNSUPPORTED_MEDIA_TYPE, "unsupported_media_type")
            }
            ApiError::Unauthorized => (StatusCode::UNAUTHORIZED, "unauthorized"),
            ApiError::Timeout(_) => (StatusCode::SERVICE_UNAVAILABLE, "timeout"),
            ApiError::Cancelled => (StatusCode::SERVICE_UNAVAILABLE, "cancelled"),
            ApiError::Internal(_) => (StatusCode::INTERNAL_SERVER_ERROR, "internal"),
        }
    }
}

impl ApiError {
    /// The answer over gRPC (the Open Inference Protocol's service): the status
    /// code of the same kind as the HTTP one, the same message.
    pub fn into_grpc_status(self) -> tonic::Status {
        use tonic::Code;
        let code = match &self {
            ApiError::UnknownModel(_) | ApiError::NoRoute(_) | ApiError::UnknownSession(_) => {
                Code::NotFound
            }
            ApiError::NoPolicy(_) | ApiError::NoSimulator { .. } => Code::FailedPrecondition,
            ApiError::Malformed(_)
            | ApiError::Invalid(_)
            | ApiError::UnsupportedMediaType { .. } => Code::InvalidArgument,
            ApiError::OverLimit(_) | ApiError::TooLarge(_) => Code::ResourceExhausted,
            ApiError::Unauthorized => Code::Unauthenticated,
            ApiError::Timeout(_) => Code::DeadlineExceeded,
            ApiError::Cancelled => Code::Cancelled,
            ApiError::Internal(_) => Code::Internal,
        };
        tonic::Status::new(code, self.client_message())
    }
}

impl From<crate::shared::cancel::Cancelled> for ApiError {
    fn from(_: crate::shared::cancel::Cancelled) -> Self {
        ApiError::Cancelled
    }
}

impl From<crate::planning::PlanningError> for ApiError {
    fn from(error: crate::planning::PlanningError) -> Self {
        use crate::planning::PlanningError;
        match error {
            PlanningError::Invalid(message) => ApiError::Invalid(message),
            PlanningError::Cancelled(_) => ApiError::Cancelled,
            PlanningError::Env(crate::envs::EnvError::Cancelled(_)) => ApiError::Cancelled,
            PlanningError::Env(e) => ApiError::Internal(e.to_string()),
        }
    }
}

impl ApiError {
    /// What the client is told. An internal error's detail may name paths or
    /// internals: it goes to the log under a fresh id, and the client gets the id.
    pub fn client_message(&self) -> String {
        match self {
            ApiError::Internal(detail) => {
                let id = format!("{:016x}", rand::random::<u64>());
                tracing::error!(error_id = %id, detail = %detail, "internal error");
                format!("internal error {id} (the server's log has the details)")
            }
            other => other.to_string(),
        }
    }
}

/// The error body.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct ErrorBody {
    pub error: ErrorDetail,
}

#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct ErrorDetail {
    /// Stable code: model_not_found, route_not_found, session_not_found, no_policy, no_simulator, malformed_body, invalid_request,
    /// over_limit, body_too_large, unsupported_media_type, unauthorized, timeout, cancelled,
    /// internal.
    pub code: String,
    /// What was wrong, naming the field and the expected value.
    pub message: String,
}

/// The KServe v2 error body.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct V2ErrorBody {
    pub error: String,
}

impl ApiError {
    /// The answer in the error shape of `route` (a path or route pattern):
    /// KServe's under `/v2`, ours elsewhere.
    pub fn into_response_for(self, route: &str) -> Response {
        if route == "/v2" || route.starts_with("/v2/") {
            self.into_v2_response()
        } else {
            self.into_response()
        }
    }

    /// The answer in KServe's error shape.
    pub fn into_v2_response(self) -> Response {
        let (status, _) = self.status_code();
        let body = V2ErrorBody {
            error: self.client_message(),
        };
        (status, Json(body)).into_response()
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let (status, code) = self.status_code();
        let body = ErrorBody {
            error: ErrorDetail {
                code: code.to_string(),
                message: self.client_message(),
            },
        };
        (status, Json(body)).into_response()
    }
}
