//! The model server: a thin axum layer over the library. `app()` builds the
//! router (versioned JSON API under /v1, KServe v2 routes, health, metrics,
//! OpenAPI and interactive docs); `serve()` runs it with graceful shutdown on
//! SIGTERM/Ctrl-C and reloads the models on SIGHUP.
//!
//! Heavy work (model steps, rollouts, MuJoCo episodes) runs off the async
//! runtime on tokio's blocking pool, at most `Limits::compute_slots` at once,
//! and stops between steps once its request is gone.

// A handler validates, calls the library and shapes: no function grows long.
#![warn(clippy::too_many_lines)]

mod batcher;
mod body;
mod error;
mod grpc;
mod metrics;
mod openapi;
mod plan_sessions;
mod registry;
mod routes;
mod rows;
mod validate;

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use axum::Router;
use axum::extract::{DefaultBodyLimit, MatchedPath, Request, State};
use axum::http::header;
use axum::middleware::{self, Next};
use axum::response::Response;
use serde::Serialize;
use tokio::sync::Semaphore;
use tracing::Instrument;
use utoipa::ToSchema;

use crate::infer::Kernel;
use crate::shared::cancel::Cancel;

pub use body::{BINARY, TensorBytes};
pub use error::{ApiError, ErrorBody, ErrorDetail, V2ErrorBody};
pub use grpc::serve_grpc;
pub use metrics::Metrics;
pub use openapi::{document as openapi_document, openapi_json};
pub use registry::{
    LoadFailure, LoadedModel, ModelKind, ModelRegistry, ReloadReport, valid_model_id,
};
pub use routes::*;
pub use rows::Rows;

/// What a client may ask for at most, and how long the server waits.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct Limits {
    /// Rows per step/act request, and start states per rollout.
    pub max_batch: usize,
    pub max_particles: usize,
    pub max_horizon: usize,
    /// batch × particles × horizon of one rollout.
    pub max_rollout_steps: usize,
    pub max_episodes: usize,
    pub max_body_bytes: usize,
    /// Largest answer, in bytes, checked before any work from the request's
    /// sizes (4 bytes a number in binary, 16 as JSON): what bounds a request's memory.
    pub max_answer_bytes: usize,
    /// Seconds before a request is answered with a timeout error.
    pub request_timeout_s: u64,
    /// Requests handled at once; more wait in line.
    pub concurrency: usize,
    /// Model computations running at once on the blocking pool.
    pub compute_slots: usize,
    /// Iterations of one `plan` call.
    pub max_plan_iterations: usize,
    /// `plan` sessions kept at once (the least recently used goes first).
    pub plan_sessions: usize,
    /// Seconds a `plan` session is kept after its last use.
    pub plan_session_ttl_s: u64,
    /// Microseconds a `step` request waits for others to the same model, to
    /// run their networks as one call (0: each alone).
    pub batch_delay_us: u64,
}

impl Default for Limits {
    fn default() -> Self {
        Self {
            max_batch: 100_000,
            max_particles: 64,
            max_horizon: 1000,
            max_rollout_steps: 5_000_000,
            max_episodes: 100,
            max_body_bytes: 64 << 20,
            max_answer_bytes: 512 << 20,
            request_timeout_s: 120,
            concurrency: 64,
            compute_slots: std::thread::available_parallelism().map_or(2, |n| n.get()),
            max_plan_iterations: 100,
            plan_sessions: 1024,
            plan_session_ttl_s: 300,
            batch_delay_us: 200,
        }
    }
}

/// How the server runs.
#[derive(Debug, Clone)]
pub struct ServerConfig {
    pub models_dir: PathBuf,
    pub limits: Limits,
    /// When set, every route except health needs `Authorization: Bearer <token>`.
    pub token: Option<String>,
    /// What evaluates the models: the fused CPU path (default) or burn.
    pub kernel: Kernel,
    /// Runs before each computation, on its blocking thread and holding its compute
    /// slot. `None` in production; tests use it to make work last exactly as long as
    /// they need (timeouts, slots), whatever the machine's speed.
    pub before_compute: Option<ComputeHook>,
}

/// A callback run at the start of every computation (see [`ServerConfig::before_compute`]).
#[derive(Clone)]
pub struct ComputeHook(pub Arc<dyn Fn() + Send + Sync>);

impl std::fmt::Debug for ComputeHook {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("ComputeHook")
    }
}

/// Shared by every handler.
#[derive(Clone)]
pub struct AppState {
    pub config: Arc<ServerConfig>,
    pub registry: Arc<ModelRegistry>,
    pub metrics: Arc<Metrics>,
    /// The `plan` route's sessions.
    pub plan_sessions: Arc<plan_sessions::PlanSessions>,
    /// Where `step` and `score` requests meet others for one computation.
    pub batcher: Arc<batcher::Batcher>,
    compute: Arc<Semaphore>,
}

impl AppState {
    /// Loads the models in `config.models_dir`; the report says what failed.
    pub fn new(config: ServerConfig) -> (Self, ReloadReport) {
        let (registry, report) = ModelRegistry::open(&config.models_dir, config.kernel);
        let compute = Arc::new(Semaphore::new(config.limits.compute_slots.max(1)));
        let metrics = Arc::new(Metrics::default());
        let state = Self {
            batcher: Arc::new(batcher::Batcher::new(
                Duration::from_micros(config.limits.batch_delay_us),
                config.limits.max_batch,
                (compute.clone(), config.before_compute.clone()),
                metrics.clone(),
            )),
            compute,
            plan_sessions: Arc::new(plan_sessions::PlanSessions::new(
                config.limits.plan_sessions,
                std::time::Duration::from_secs(config.limits.plan_session_ttl_s),
            )),
            config: Arc::new(config),
            registry: Arc::new(registry),
            metrics,
        };
        (state, report)
    }

    /// The model called `id`.
    pub fn model(&self, id: &str) -> Result<Arc<LoadedModel>, ApiError> {
        self.registry
            .get(id)
            .ok_or_else(|| ApiError::UnknownModel(id.chars().take(128).collect()))
    }

    /// Runs `work` on the blocking pool once a compute slot is free.
    ///
    /// The slot belongs to the blocking work, not to the request's future: when a
    /// request times out or its client hangs up, the future is dropped but the slot
    /// stays taken until the work itself has finished, so abandoned requests cannot
    /// pile up more computations than there are slots. Dropping the future also
    /// sets the [`Cancel`] flag `work` is given: long work checks it between steps
    /// and stops early, freeing the slot for the next request.
    pub async fn compute<T: Send + 'static>(
        &self,
        work: impl FnOnce(&Cancel) -> Result<T, ApiError> + Send + 'static,
    ) -> Result<T, ApiError> {
        let slot = self
            .compute
            .clone()
            .acquire_owned()
            .await
            .map_err(|e| ApiError::Internal(e.to_string()))?;
        let cancel = Cancel::default();
        // Dropped with this future: on completion (harmless), timeout or hang-up.
        let _cancel_if_abandoned = cancel.on_drop();
        let hook = self.config.before_compute.clone();
        let metrics = self.metrics.clone();
        tokio::task::spawn_blocking(move || {
            let _slot = slot;
            if let Some(ComputeHook(hook)) = hook {
                hook();
            }
            let result = cancel
                .check()
                .map_err(ApiError::from)
                .and_then(|()| work(&cancel));
            if matches!(result, Err(ApiError::Cancelled)) {
                metrics.cancelled();
            }
            result
        })
        .await
        .map_err(|e| ApiError::Internal(format!("computation failed: {e}")))?
    }
}

/// The whole HTTP application.
pub fn app(state: AppState) -> Router {
    let limits = state.config.limits.clone();
    // With a token, the spec and the docs need it too: they list every model
    // route, which a deployment that sets a token may not want to show.
    let protected = Router::from(routes::api_routes())
        .merge(openapi::docs_routes(&limits))
        .route_layer(middleware::from_fn_with_state(state.clone(), require_token));
    // The fallback goes in before the layers, so unknown routes are timed,
    // logged and counted like the others.
    Router::new()
        .merge(protected)
        .merge(Router::from(routes::health_routes()))
        .fallback(|uri: axum::http::Uri| async move { ApiError::NoRoute(uri.path().to_string()) })
        .layer(middleware::from_fn_with_state(
            state.clone(),
            timeout_and_metrics,
        ))
        .layer(DefaultBodyLimit::max(limits.max_body_bytes))
        .layer(tower::limit::ConcurrencyLimitLayer::new(
            limits.concurrency.max(1),
        ))
        .with_state(state)
}

/// Bearer-token check for everything but health.
async fn require_token(State(state): State<AppState>, request: Request, next: Next) -> Response {
    if let Some(token) = &state.config.token {
        let given = request
            .headers()
            .get(header::AUTHORIZATION)
            .and_then(|v| v.to_str().ok())
            .and_then(|v| v.strip_prefix("Bearer "));
        if !given.is_some_and(|given| token_matches(given, token)) {
            return ApiError::Unauthorized.into_response_for(request.uri().path());
        }
    }
    next.run(request).await
}

/// Whether `given` is `token`, in a time that does not depend on where they
/// differ or on their lengths: both are hashed to fixed-length digests, compared
/// byte by byte without an early exit.
fn token_matches(given: &str, token: &str) -> bool {
    use sha2::{Digest, Sha256};
    let (a, b) = (Sha256::digest(given), Sha256::digest(token));
    let difference = a
        .iter()
        .zip(b.iter())
        .fold(0u8, |acc, (x, y)| std::hint::black_box(acc | (x ^ y)));
    difference == 0
}

/// Per-request timeout (answered as a JSON error), request metrics, and one
/// log line per request in a `request` span (method, matched route).
async fn timeout_and_metrics(
    State(state): State<AppState>,
    request: Request,
    next: Next,
) -> Response {
    let route = request
        .extensions()
        .get::<MatchedPath>()
        .map_or_else(|| "unmatched".to_string(), |p| p.as_str().to_string());
    let span = tracing::info_span!("request", method = %request.method(), route = %route);
    let started = Instant::now();
    let seconds = state.config.limits.request_timeout_s;
    let answer = tokio::time::timeout(Duration::from_secs(seconds), next.run(request));
    let response = match answer.instrument(span.clone()).await {
        Ok(response) => response,
        Err(_) => ApiError::Timeout(seconds).into_response_for(&route),
    };
    let (status, elapsed) = (response.status().as_u16(), started.elapsed());
    span.in_scope(|| tracing::info!(status, latency_ms = elapsed.as_secs_f64() * 1e3, "answered"));
    state.metrics.request(&route, status, elapsed.as_secs_f64());
    response
}

/// Serves `state` on `addr` until SIGTERM or Ctrl-C; SIGHUP reloads the models.
pub async fn serve(state: AppState, listener: tokio::net::TcpListener) -> std::io::Result<()> {
    #[cfg(unix)]
    {
        let registry = state.registry.clone();
        tokio::spawn(async move {
            use tokio::signal::unix::{SignalKind, signal};
            let Ok(mut hangups) = signal(SignalKind::hangup()) else {
                return;
            };
            while hangups.recv().await.is_some() {
                let registry = registry.clone();
                let report = tokio::task::spawn_blocking(move || registry.reload()).await;
                match report {
                    Ok(report) => tracing::info!(
                        loaded = ?report.loaded,
                        failed = ?report.failed,
                        "SIGHUP: models reloaded"
                    ),
                    Err(e) => tracing::error!(error = %e, "SIGHUP: the reload failed"),
                }
            }
        });
    }
    use axum::serve::ListenerExt;
    // Small answers leave at once: Nagle's algorithm would hold a batch-1
    // answer for the client's delayed ACK.
    let listener = listener.tap_io(|tcp| {
        let _ = tcp.set_nodelay(true);
    });
    axum::serve(
        listener,
        app(state).into_make_service_with_connect_info::<SocketAddr>(),
    )
    .with_graceful_shutdown(shutdown_signal())
    .await
}

async fn shutdown_signal() {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let terminate = async {
        use tokio::signal::unix::{SignalKind, signal};
        match signal(SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let terminate = std::future::pending::<()>();
    tokio::select! {
        () = ctrl_c => {},
        () = terminate => {},
    }
}
