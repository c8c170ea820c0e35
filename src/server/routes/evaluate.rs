//! MuJoCo-backed checks: `POST /v1/evaluate` runs a loaded policy in the real
//! task; `POST /v1/models/{id}/validate` compares the model's open-loop
//! prediction with the real task along given actions.

use axum::Json;
use axum::extract::{Path, State};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::fields::{DEFAULT_EPISODES, integer, one, optional_integer};
use crate::agent::ActionMode;
use crate::envs::{
    EnvError, EvaluationConfig, EvaluationReport, TaskConfig, evaluate_or_cancel as run_episodes,
};
use crate::sde::{TaskComparisonConfig, compare_with_task};
use crate::server::body::RawBody;
use crate::server::registry::LoadedModel;
use crate::server::rows::{Rows, split_rows};
use crate::server::validate::within;
use crate::server::{ApiError, AppState};

#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct EvaluateRequest {
    /// The model whose policy runs, in the model's task.
    pub model: String,
    /// Episodes: 10 by default, or the server's limit when that is lower;
    /// episode i resets with seed + i (mod 2⁶⁴).
    #[serde(default, deserialize_with = "optional_integer")]
    #[schema(minimum = 1)]
    pub episodes: Option<usize>,
    #[serde(default)]
    #[serde(deserialize_with = "integer")]
    pub seed: u64,
    /// deterministic (default) or sampled actions.
    #[serde(default)]
    pub mode: ActionMode,
}

#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct EvaluateResponse {
    pub model: String,
    pub task: String,
    /// Returns, lengths and D4RL normalised scores (× 100) per episode, and their mean and std.
    #[serde(flatten)]
    pub report: EvaluationReport,
}

/// Runs the model's policy in the real MuJoCo task.
#[utoipa::path(post, path = "/v1/evaluate", tag = "evaluation",
    request_body = EvaluateRequest,
    responses(
        (status = 200, description = "Success", body = EvaluateResponse),
        (status = 404, description = "Unknown model", body = crate::server::ErrorBody),
        (status = 409, body = crate::server::ErrorBody, description = "The model has no policy, or its system no simulator"),
        (status = 422, description = "Wrong dimensions, non-finite values, an empty batch, or over a limit", body = crate::server::ErrorBody),
    ))]
pub async fn evaluate(
    State(state): State<AppState>,
    body: RawBody,
) -> Result<Json<EvaluateResponse>, ApiError> {
    let r: EvaluateRequest = body.json().await?;
    let model = state.model(&r.model)?;
    let task = simulator(&model)?;
    if model.policy.is_none() {
        return Err(ApiError::NoPolicy(r.model));
    }
    let max_episodes = state.config.limits.max_episodes;
    let episodes = r.episodes.unwrap_or(DEFAULT_EPISODES.min(max_episodes));
    within("episodes", episodes, max_episodes)?;
    state.metrics.batch("evaluate", &r.model, episodes);
    let config = EvaluationConfig::new(task.clone(), episodes, r.seed);
    let worker = model.clone();
    let report = state
        .compute(move |cancel| {
            let policy = worker
                .batch_policy(r.mode)
                .ok_or_else(|| ApiError::NoPolicy(worker.id.clone()))?;
            run_episodes(policy.as_ref(), &config, cancel).map_err(|e| match e {
                EnvError::Cancelled(_) => ApiError::Cancelled,
                e => ApiError::Internal(e.to_string()),
            })
        })
        .await?;
    Ok(Json(EvaluateResponse {
        model: r.model,
        task: task.task.to_string(),
        report,
    }))
}

#[derive(Debug, Clone, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct ValidateRequest {
    /// Actions to apply, `[horizon][act_dim]` (act_dim: the model's).
    #[schema(value_type = Vec<Vec<f32>>, min_items = 1)]
    pub actions: Rows,
    /// Reset seed of the real task (the start state).
    #[serde(default)]
    #[serde(deserialize_with = "integer")]
    pub seed: u64,
    /// Model samples averaged per step (default 1).
    #[serde(default = "one")]
    #[schema(minimum = 1)]
    #[serde(deserialize_with = "integer")]
    pub particles: usize,
    /// Multiplies the model's noise (default 0: the drift alone).
    #[serde(default)]
    #[schema(minimum = 0)]
    pub noise_scale: f32,
}

#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct ValidateResponse {
    pub model: String,
    /// Steps compared: until the horizon, or until the real task or the model terminated.
    pub steps: usize,
    /// Real observations, `[steps + 1][obs_dim]`.
    pub real_states: Vec<Vec<f32>>,
    /// The model's (particle-mean) observations, `[steps + 1][obs_dim]`.
    pub model_states: Vec<Vec<f32>>,
    /// RMSE over observation entries after each step, physical units: `[steps]`.
    pub rmse: Vec<f32>,
    /// The same with each entry divided by the dataset's std.
    pub normalized_rmse: Vec<f32>,
}

/// Compares the model's open-loop prediction with the real MuJoCo task.
#[utoipa::path(post, path = "/v1/models/{id}/validate", tag = "evaluation",
    params(("id" = String, Path, description = "Model id")),
    request_body = ValidateRequest,
    responses(
        (status = 200, description = "Success", body = ValidateResponse),
        (status = 404, description = "Unknown model", body = crate::server::ErrorBody),
        (status = 409, body = crate::server::ErrorBody, description = "The model's system has no simulator"),
        (status = 422, description = "Wrong dimensions, non-finite values, an empty batch, or over a limit", body = crate::server::ErrorBody),
    ))]
pub async fn validate(
    State(state): State<AppState>,
    Path(id): Path<String>,
    body: RawBody,
) -> Result<Json<ValidateResponse>, ApiError> {
    let r: ValidateRequest = body.json().await?;
    let model = state.model(&id)?;
    let task = simulator(&model)?;
    let (obs_dim, act_dim) = (model.obs_dim(), model.act_dim());
    let limits = &state.config.limits;
    let horizon = r.actions.len();
    within("horizon (rows of actions)", horizon, limits.max_horizon)?;
    let actions = r.actions.into_matrix("actions", act_dim)?;
    within("particles", r.particles, limits.max_particles)?;
    if !r.noise_scale.is_finite() || r.noise_scale < 0.0 {
        return Err(ApiError::Invalid(
            "`noise_scale` must be a finite number ≥ 0".into(),
        ));
    }
    state.metrics.batch("validate", &id, horizon * r.particles);
    let config = TaskComparisonConfig {
        seed: r.seed,
        particles: r.particles,
        noise_scale: r.noise_scale,
    };
    let worker = model.clone();
    let comparison = state
        .compute(move |cancel| {
            let std = worker.observation_std();
            compare_with_task(
                worker.batch_dynamics(),
                task,
                &worker.rules,
                std,
                &actions,
                &config,
                cancel,
            )
            .map_err(|e| match e {
                EnvError::Cancelled(_) => ApiError::Cancelled,
                e @ EnvError::Model { .. } => ApiError::Internal(e.to_string()),
                e => ApiError::Invalid(e.to_string()),
            })
        })
        .await?;
    Ok(Json(ValidateResponse {
        model: id,
        steps: comparison.steps,
        real_states: split_rows(&comparison.real_states, obs_dim),
        model_states: split_rows(&comparison.model_states, obs_dim),
        rmse: comparison.rmse,
        normalized_rmse: comparison.normalized_rmse,
    }))
}

/// The MuJoCo task `model` is of; a 409 for a system whose file has no `[mujoco]` table.
fn simulator(model: &LoadedModel) -> Result<TaskConfig, ApiError> {
    model
        .system
        .simulator()
        .ok_or_else(|| ApiError::NoSimulator {
            model: model.id.clone(),
            system: model.system.name(),
        })
}
