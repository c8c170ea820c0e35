//! What is loaded: `GET /v1/models` and `GET /v1/models/{id}`.

use axum::Json;
use axum::extract::{Path, State};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use crate::server::{ApiError, AppState, LoadedModel};

/// One loaded model in brief.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct ModelSummary {
    pub id: String,
    /// hopper, halfcheetah or walker2d.
    pub task: String,
    /// d4rl or neorl observations.
    pub layout: String,
    pub obs_dim: usize,
    pub act_dim: usize,
    /// Integration step (s).
    pub dt: f64,
    /// NUNO^R: rewards come from the model.
    pub reward_model: bool,
    pub has_policy: bool,
}

#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct ModelList {
    pub models: Vec<ModelSummary>,
}

/// Everything about a model.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct ModelDetail {
    #[serde(flatten)]
    pub summary: ModelSummary,
    /// Observation indices of positions and velocities, and each position's velocity.
    #[schema(value_type = Object)]
    pub state_split: serde_json::Value,
    /// The neural SDE's hyperparameters (sizes, diffusion bounds).
    #[schema(value_type = Object)]
    pub hyperparameters: serde_json::Value,
    /// ε(h, α): `values[i][j]` for `horizons[i]`, `alphas[j]`.
    #[schema(value_type = Object)]
    pub thresholds: serde_json::Value,
    /// Fit summary and configuration.
    #[schema(value_type = Object)]
    pub training: serde_json::Value,
    #[schema(value_type = Object)]
    pub dataset: serde_json::Value,
    /// The policy's provenance (preset, epoch, score), if one is loaded.
    #[schema(value_type = Object)]
    pub policy: serde_json::Value,
}

pub(crate) fn summary(model: &LoadedModel) -> ModelSummary {
    let spec = &model.metadata.spec;
    ModelSummary {
        id: model.id.clone(),
        task: model.task.name.to_string(),
        layout: serde_json::to_value(model.task.layout)
            .ok()
            .and_then(|v| v.as_str().map(String::from))
            .unwrap_or_default(),
        obs_dim: spec.obs_dim,
        act_dim: spec.act_dim,
        dt: spec.dt,
        reward_model: model.metadata.model.reward_model,
        has_policy: model.policy.is_some(),
    }
}

/// The loaded models.
#[utoipa::path(get, path = "/v1/models", tag = "models", responses((status = 200, description = "Success", body = ModelList)))]
pub async fn list_models(State(state): State<AppState>) -> Json<ModelList> {
    Json(ModelList {
        models: state
            .registry
            .snapshot()
            .values()
            .map(|m| summary(m))
            .collect(),
    })
}

/// One model: task, dims, state split, dt, hyperparameters, thresholds, training summary, policy.
#[utoipa::path(get, path = "/v1/models/{id}", tag = "models",
    params(("id" = String, Path, description = "Model id (its directory name)")),
    responses((status = 200, description = "Success", body = ModelDetail), (status = 404, description = "Unknown model", body = crate::server::ErrorBody)))]
pub async fn get_model(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Json<ModelDetail>, ApiError> {
    let model = state.model(&id)?;
    let m = &model.metadata;
    let value = |v: serde_json::Result<serde_json::Value>| v.unwrap_or_default();
    Ok(Json(ModelDetail {
        summary: summary(&model),
        state_split: value(serde_json::to_value(&m.spec.split)),
        hyperparameters: value(serde_json::to_value(&m.model)),
        thresholds: value(serde_json::to_value(&m.provenance.thresholds)),
        training: serde_json::json!({
            "summary": m.provenance.training,
            "fit": m.provenance.fit,
        }),
        dataset: value(serde_json::to_value(&m.provenance.dataset)),
        policy: model
            .policy
            .as_ref()
            .map(|(_, p)| value(serde_json::to_value(&p.provenance)))
            .unwrap_or_default(),
    }))
}
