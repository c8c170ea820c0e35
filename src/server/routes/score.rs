//! `POST /v1/models/{id}/score`: candidate action sequences scored in the
//! model from a batch of start states, one answer per candidate (what a
//! sampling planner needs: MPPI's and CEM's population, not trajectories).

use axum::extract::{Path, State};
use axum::http::HeaderMap;
use axum::response::Response;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::fields::{integer, one, unit, yes};
use super::scoring::{CostRequest, ScoringFields};
use crate::artifact::NamedTensors;
use crate::planning::{CandidateScore, Candidates, score_sequences};
use crate::server::body::{
    Format, RawBody, TensorBytes, answer_format, json_response, tensors_response,
};
use crate::server::rows::Rows;
use crate::server::validate::{answer_within, clip_actions, within};
use crate::server::{ApiError, AppState, LoadedModel};

#[derive(Debug, Clone, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct ScoreRequest {
    /// Start observations, `[batch][obs_dim]` (obs_dim: the model's).
    #[schema(value_type = Vec<Vec<f32>>, min_items = 1)]
    pub states: Rows,
    /// Each start's candidates, `[batch][candidates][horizon][act_dim]`
    /// (act_dim: the model's); or give `shared_actions`.
    #[serde(default)]
    #[schema(value_type = Option<Vec<Vec<Vec<Vec<f32>>>>>)]
    pub actions: Option<Vec<Vec<Rows>>>,
    /// Candidates every start shares, `[candidates][horizon][act_dim]`.
    #[serde(default)]
    #[schema(value_type = Option<Vec<Vec<Vec<f32>>>>)]
    pub shared_actions: Option<Vec<Rows>>,
    /// Steps H of every candidate. batch × candidates × particles × horizon is
    /// bounded by `--max-rollout-steps`.
    #[schema(minimum = 1)]
    #[serde(deserialize_with = "integer")]
    pub horizon: usize,
    /// Samples of each candidate (default 1).
    #[serde(default = "one")]
    #[schema(minimum = 1)]
    #[serde(deserialize_with = "integer")]
    pub particles: usize,
    /// γ of the returns (default 1: undiscounted).
    #[serde(default = "unit")]
    #[schema(exclusive_minimum = 0, maximum = 1)]
    pub discount: f64,
    /// λ of the penalised return Σ γ^t (r_t − λ·η_t) (default 1).
    #[serde(default = "unit")]
    #[schema(minimum = 0)]
    pub penalty: f64,
    /// The share of particles whose returns `cvar_return` averages, worst first.
    #[serde(default)]
    #[schema(exclusive_minimum = 0, maximum = 1)]
    pub cvar_alpha: Option<f64>,
    /// CVaR level α of the truncation ε(H, α) from the model's table
    /// (`GET /v1/models/{id}`); or give `threshold`.
    #[serde(default)]
    #[schema(exclusive_minimum = 0, maximum = 1)]
    pub alpha: Option<f64>,
    /// An explicit truncation threshold instead of α.
    #[serde(default)]
    pub threshold: Option<f32>,
    #[serde(default)]
    #[serde(deserialize_with = "integer")]
    pub seed: u64,
    /// Multiplies ε (default: the model's own `sample_noise_scale`).
    #[serde(default)]
    #[schema(minimum = 0)]
    pub noise_scale: Option<f32>,
    /// Clip actions outside the model's action box into it (default); false
    /// answers 422 instead.
    #[serde(default = "yes")]
    pub clip: bool,
    /// Your own costs on the observations reached, added to the reward or replacing it.
    #[serde(default)]
    pub cost: Option<CostRequest>,
}

#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct ScoreResponse {
    pub model: String,
    pub batch: usize,
    pub candidates: usize,
    pub horizon: usize,
    pub particles: usize,
    /// The truncation threshold used, if any.
    pub threshold: Option<f32>,
    /// The scale of ε the samples were drawn at.
    pub noise_scale: f32,
    /// Action rows (candidate × step) clipped into the action box.
    pub clipped_rows: usize,
    /// `[batch][candidates]`.
    pub scores: Vec<Vec<CandidateScore>>,
}

/// Scores every candidate sequence from its start state: per candidate the
/// mean and penalised returns over `particles` samples, their CVaR, η along
/// the way, where ε(H, α) truncated and the shares that terminated or
/// diverged. With `Accept: application/octet-stream` the answer is a
/// safetensors file of `[batch, candidates]` tensors named as the JSON
/// fields (`cvar_return` NaN when not asked for, `truncated_at` −1 where
/// nothing truncated); `noise_scale` and `clipped_rows` in its metadata.
#[utoipa::path(post, path = "/v1/models/{id}/score", tag = "models",
    params(("id" = String, Path, description = "Model id")),
    request_body = ScoreRequest,
    responses(
        (status = 200, description = "Success", content((ScoreResponse = "application/json"), (TensorBytes = "application/octet-stream"))),
        (status = 400, description = "Malformed body", body = crate::server::ErrorBody),
        (status = 404, description = "Unknown model", body = crate::server::ErrorBody),
        (status = 422, description = "Wrong dimensions, non-finite values, an empty batch, or over a limit", body = crate::server::ErrorBody),
        (status = 503, description = "Timed out or cancelled", body = crate::server::ErrorBody),
    ))]
pub async fn score(
    State(state): State<AppState>,
    Path(id): Path<String>,
    headers: HeaderMap,
    body: RawBody,
) -> Result<Response, ApiError> {
    let answer = answer_format(&headers);
    let mut r: ScoreRequest = body.json().await?;
    let model = state.model(&id)?;
    let limits = &state.config.limits;
    let batch = r.states.len();
    within("batch (rows of states)", batch, limits.max_batch)?;
    within("horizon", r.horizon, limits.max_horizon)?;
    within("particles", r.particles, limits.max_particles)?;
    let starts = std::mem::take(&mut r.states).into_matrix("states", model.obs_dim())?;
    let (mut sequences, candidates) = candidate_actions(&mut r, &model, batch)?;
    within("candidates", candidates, limits.max_batch)?;
    let clipped_rows = clip_actions("actions", &mut sequences, &model.action_space, r.clip)?;
    let rows = batch * candidates * r.particles;
    within(
        "batch × candidates × particles × horizon",
        rows * r.horizon,
        limits.max_rollout_steps,
    )?;
    // The rollout behind the scores holds every step of every particle.
    answer_within(
        "batch × candidates × particles × ((horizon + 1)·obs_dim + horizon·(act_dim + 4))",
        rows * ((r.horizon + 1) * model.obs_dim() + r.horizon * (model.act_dim() + 4)),
        Format::Binary,
        limits.max_answer_bytes,
    )?;
    let config = ScoringFields {
        horizon: r.horizon,
        particles: r.particles,
        discount: r.discount,
        penalty: r.penalty,
        cvar_alpha: r.cvar_alpha,
        alpha: r.alpha,
        threshold: r.threshold,
        noise_scale: r.noise_scale,
        cost: r.cost.as_ref(),
    }
    .config(&model)?;
    let noise_scale = config.noise_scale;
    state.metrics.batch("score", &id, rows * r.horizon);
    let worker = model.clone();
    state
        .compute(move |cancel| {
            let mut rng = ChaCha8Rng::seed_from_u64(r.seed);
            let given = Candidates {
                starts: &starts,
                sequences: &sequences,
                per_start: candidates,
            };
            let scores = score_sequences(
                worker.batch_dynamics(),
                &worker.rules,
                &given,
                &config,
                &mut rng,
                cancel,
            )?;
            if answer == Format::Binary {
                let tensors = binary_scores(&scores, [batch, candidates]);
                return tensors_response(&tensors, noise_scale, clipped_rows);
            }
            json_response(&ScoreResponse {
                model: id,
                batch,
                candidates,
                horizon: config.horizon,
                particles: config.particles,
                threshold: config.threshold,
                noise_scale,
                clipped_rows,
                scores: scores.chunks(candidates).map(<[_]>::to_vec).collect(),
            })
        })
        .await
}

/// The candidates, flat `[batch, candidates, horizon, act_dim]`, and their
/// count per start: each start's own, or the shared ones repeated per start.
fn candidate_actions(
    r: &mut ScoreRequest,
    model: &LoadedModel,
    batch: usize,
) -> Result<(Vec<f32>, usize), ApiError> {
    let (horizon, act_dim) = (r.horizon, model.act_dim());
    let flat = |field: &str, candidates: Vec<Rows>| -> Result<Vec<f32>, ApiError> {
        let mut out = Vec::with_capacity(candidates.len() * horizon * act_dim);
        for (n, sequence) in candidates.into_iter().enumerate() {
            if sequence.len() != horizon {
                return Err(ApiError::Invalid(format!(
                    "`{field}[{n}]` has {} steps, the horizon is {horizon}",
                    sequence.len()
                )));
            }
            out.extend(sequence.into_matrix(&format!("{field}[{n}]"), act_dim)?);
        }
        Ok(out)
    };
    match (r.actions.take(), r.shared_actions.take()) {
        (Some(per_start), None) => {
            if per_start.len() != batch {
                return Err(ApiError::Invalid(format!(
                    "`actions` has candidates for {} start states, `states` has {batch}",
                    per_start.len()
                )));
            }
            let candidates = per_start[0].len();
            let mut out = Vec::new();
            for (b, start) in per_start.into_iter().enumerate() {
                if start.len() != candidates {
                    return Err(ApiError::Invalid(format!(
                        "`actions[{b}]` has {} candidates, `actions[0]` has {candidates}",
                        start.len()
                    )));
                }
                out.extend(flat(&format!("actions[{b}]"), start)?);
            }
            Ok((out, candidates))
        }
        (None, Some(shared)) => {
            let candidates = shared.len();
            let one = flat("shared_actions", shared)?;
            Ok((one.repeat(batch), candidates))
        }
        _ => Err(ApiError::Invalid(
            "give `actions` (per start) or `shared_actions`, exactly one".into(),
        )),
    }
}

/// The scores as `[batch, candidates]` tensors, one per field.
fn binary_scores(scores: &[CandidateScore], shape: [usize; 2]) -> NamedTensors {
    let field = |value: fn(&CandidateScore) -> f64| -> (Vec<usize>, Vec<f32>) {
        (
            shape.to_vec(),
            scores.iter().map(|s| value(s) as f32).collect(),
        )
    };
    NamedTensors::from([
        ("mean_return".into(), field(|s| s.mean_return)),
        ("penalized_return".into(), field(|s| s.penalized_return)),
        (
            "cvar_return".into(),
            field(|s| s.cvar_return.unwrap_or(f64::NAN)),
        ),
        ("accumulated_eta".into(), field(|s| s.accumulated_eta)),
        ("max_eta".into(), field(|s| s.max_eta)),
        (
            "truncated_at".into(),
            field(|s| s.truncated_at.map_or(-1.0, |k| k as f64)),
        ),
        ("terminated".into(), field(|s| s.terminated)),
        ("diverged".into(), field(|s| s.diverged)),
    ])
}
