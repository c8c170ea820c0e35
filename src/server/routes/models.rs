//! What is loaded: `GET /v1/models` and `GET /v1/models/{id}`.

use axum::Json;
use axum::extract::{Path, State};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use crate::artifact::ModelFolder;
use crate::envs::{System, SystemReward, SystemSpec};
use crate::server::{ApiError, AppState, LoadedModel, ModelKind};

/// One loaded model in brief.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct ModelSummary {
    pub id: String,
    /// neural-sde (NUNO's, `fit-model`) or gaussian-ensemble (MOPO's, `fit-ensemble`).
    pub kind: ModelKind,
    /// A built-in task (hopper, halfcheetah, walker2d, swimmer, invertedpendulum, ant);
    /// or the name a system file gives.
    pub task: String,
    /// d4rl or neorl observations; `system` for a system described in a file.
    pub layout: String,
    pub obs_dim: usize,
    pub act_dim: usize,
    /// Seconds of the task one model step covers.
    pub dt: f64,
    /// Rewards come from the model (NUNO^R, the ensemble).
    pub reward_model: bool,
    /// The scale of ε the model samples at unless a request gives `noise_scale`:
    /// 1 is the calibrated Σ; a neural SDE fitted with NUNO's code's convention
    /// records sqrt(dt).
    pub sample_noise_scale: f32,
    pub has_policy: bool,
    /// The action box's lower and upper bounds, `[act_dim]` each: actions
    /// outside it are clipped into it (or refused with `clip: false`).
    pub action_low: Vec<f32>,
    pub action_high: Vec<f32>,
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
    /// Observation indices of positions and velocities, and each position's
    /// velocity (the neural SDE's; null for an ensemble).
    #[schema(value_type = Object)]
    pub state_split: serde_json::Value,
    /// The model's hyperparameters (the SDE's sizes and diffusion bounds; the
    /// ensemble's members, elites, layers, weight decay).
    #[schema(value_type = Object)]
    pub hyperparameters: serde_json::Value,
    /// ε(h, α): `values[i][j]` for `horizons[i]`, `alphas[j]` (null for an ensemble).
    #[schema(value_type = Object)]
    pub thresholds: serde_json::Value,
    /// Fit summary and configuration (an ensemble's: elites, holdout MSE, epochs).
    #[schema(value_type = Object)]
    pub training: serde_json::Value,
    #[schema(value_type = Object)]
    pub dataset: serde_json::Value,
    /// The policy's provenance (preset, epoch, score), if one is loaded.
    #[schema(value_type = Object)]
    pub policy: serde_json::Value,
    /// A system described in a file: its names, dt, pairs, reward and
    /// bounds (absent for a built-in task).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub system: Option<SystemDescription>,
}

/// What a system file declares, by name.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct SystemDescription {
    pub name: String,
    /// Seconds between consecutive observations.
    pub dt: f64,
    pub observations: Vec<String>,
    pub actions: Vec<String>,
    pub action_low: Vec<f64>,
    pub action_high: Vec<f64>,
    /// `[position, velocity]`: d position/dt = velocity (eq. 8's prior).
    pub pairs: Vec<[String; 2]>,
    /// Positions the drift sees through cos and sin.
    pub angles: Vec<String>,
    /// `learned` or the reward expression.
    pub reward: String,
    /// Observation → `[low, high]`: an episode ends outside.
    pub bounds: std::collections::BTreeMap<String, [f64; 2]>,
}

impl SystemDescription {
    fn of(spec: &SystemSpec) -> Self {
        let name = |i: usize| spec.observations[i].clone();
        let split = &spec.split;
        Self {
            name: spec.name.clone(),
            dt: spec.dt,
            observations: spec.observations.clone(),
            actions: spec.actions.clone(),
            action_low: spec.action_low.clone(),
            action_high: spec.action_high.clone(),
            pairs: (split.positions.iter().zip(&split.position_velocity))
                .map(|(&p, &v)| [name(p), name(v)])
                .collect(),
            angles: split.angles.iter().map(|&a| name(a)).collect(),
            reward: match &spec.reward {
                SystemReward::Learned => "learned".into(),
                SystemReward::Expression(e) => e.text().into(),
            },
            bounds: (spec.bounds.iter())
                .map(|b| (name(b.index), [b.low, b.high]))
                .collect(),
        }
    }
}

pub(crate) fn summary(model: &LoadedModel) -> ModelSummary {
    ModelSummary {
        id: model.id.clone(),
        kind: model.kind(),
        task: model.system.name(),
        layout: match &model.system {
            System::Task(task) => serde_json::to_value(task.layout)
                .ok()
                .and_then(|v| v.as_str().map(String::from))
                .unwrap_or_default(),
            System::File(_) => "system".into(),
        },
        obs_dim: model.obs_dim(),
        act_dim: model.act_dim(),
        dt: model.step_seconds,
        reward_model: model.reward_model(),
        sample_noise_scale: model.batch_dynamics().sample_noise_scale(),
        has_policy: model.policy.is_some(),
        action_low: model.action_space.iter().map(|&(low, _)| low).collect(),
        action_high: model.action_space.iter().map(|&(_, high)| high).collect(),
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
    let value = |v: serde_json::Result<serde_json::Value>| v.unwrap_or_default();
    let (state_split, hyperparameters, thresholds, training, dataset) = match &model.folder {
        ModelFolder::NeuralSde { metadata: m, .. } => (
            value(serde_json::to_value(&m.spec.split)),
            value(serde_json::to_value(&m.model)),
            value(serde_json::to_value(&m.provenance.thresholds)),
            serde_json::json!({
                "summary": m.provenance.training,
                "fit": m.provenance.fit,
            }),
            value(serde_json::to_value(&m.provenance.dataset)),
        ),
        ModelFolder::GaussianEnsemble { metadata: m, .. } => (
            serde_json::Value::Null,
            value(serde_json::to_value(&m.config)),
            serde_json::Value::Null,
            serde_json::json!({
                "elites": m.elites,
                "holdout_mse": m.holdout_mse,
                "epochs": m.epochs,
            }),
            value(serde_json::to_value(&m.dataset)),
        ),
    };
    Ok(Json(ModelDetail {
        summary: summary(&model),
        state_split,
        hyperparameters,
        thresholds,
        training,
        dataset,
        policy: model
            .policy
            .as_ref()
            .map(|(_, p)| value(serde_json::to_value(&p.provenance)))
            .unwrap_or_default(),
        system: match &model.system {
            System::File(spec) => Some(SystemDescription::of(spec)),
            System::Task(_) => None,
        },
    }))
}
