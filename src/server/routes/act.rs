//! `POST /v1/models/{id}/act`: the model's policy on a batch of states.

use axum::extract::{Path, State};
use axum::response::Response;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::fields::integer;
use utoipa::ToSchema;

use crate::agent::ActionMode;
use crate::server::body::{RawBody, json_response};
use crate::server::rows::{Rows, split_rows};
use crate::server::validate::within;
use crate::server::{ApiError, AppState};

#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct ActRequest {
    /// Observations, `[batch][obs_dim]` (obs_dim: the model's).
    #[schema(value_type = Vec<Vec<f32>>, min_items = 1)]
    pub states: Rows,
    /// deterministic (tanh of the mean, the default) or sampled.
    #[serde(default)]
    pub mode: ActionMode,
    /// Seed of the policy's noise when sampled.
    #[serde(default)]
    #[serde(deserialize_with = "integer")]
    pub seed: u64,
}

impl ActRequest {
    /// The policy's deterministic actions in `states`.
    pub fn new(states: Rows) -> Self {
        Self {
            states,
            mode: ActionMode::default(),
            seed: 0,
        }
    }
}

#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct ActResponse {
    pub model: String,
    /// `[batch][act_dim]`, inside the task's action box.
    pub actions: Vec<Vec<f32>>,
}

/// Policy actions for a batch of observations.
#[utoipa::path(post, path = "/v1/models/{id}/act", tag = "models",
    params(("id" = String, Path, description = "Model id")),
    request_body = ActRequest,
    responses(
        (status = 200, description = "Success", body = ActResponse),
        (status = 404, description = "Unknown model", body = crate::server::ErrorBody),
        (status = 409, body = crate::server::ErrorBody, description = "The model has no policy"),
        (status = 422, description = "Wrong dimensions, non-finite values, an empty batch, or over a limit", body = crate::server::ErrorBody),
    ))]
pub async fn act(
    State(state): State<AppState>,
    Path(id): Path<String>,
    body: RawBody,
) -> Result<Response, ApiError> {
    let r: ActRequest = body.json().await?;
    let model = state.model(&id)?;
    let Some((actor, _)) = model.policy.as_ref() else {
        return Err(ApiError::NoPolicy(id));
    };
    let obs_dim = actor.config.obs_dim;
    let batch = r.states.len();
    within(
        "batch (rows of states)",
        batch,
        state.config.limits.max_batch,
    )?;
    let states = r.states.into_matrix("states", obs_dim)?;
    state.metrics.batch("act", &id, batch);
    let act_dim = actor.config.act_dim;
    let worker = model.clone();
    // Serialised in the compute work too: the answer is batch-sized.
    state
        .compute(move |_| {
            let policy = worker
                .batch_policy(r.mode)
                .ok_or_else(|| ApiError::NoPolicy(worker.id.clone()))?;
            let mut rng = ChaCha8Rng::seed_from_u64(r.seed);
            let actions = policy.act(&states, &mut rng);
            json_response(&ActResponse {
                model: id,
                actions: split_rows(&actions, act_dim),
            })
        })
        .await
}
