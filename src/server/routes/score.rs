//! `POST /v1/models/{id}/score`: candidate action sequences scored in the
//! model from a batch of start states, one answer per candidate (what a
//! sampling planner needs: MPPI's and CEM's population, not trajectories).

use std::collections::HashMap;

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
use crate::planning::{CandidateScore, Candidates, PlanningError, ScoreConfig, score_sequences};
use crate::server::batcher::{ScoreWork, Work};
use crate::server::body::{
    Format, RawBody, TensorBytes, answer_format, json_response, metadata_option,
    refuse_unknown_metadata, tensors_response,
};
use crate::server::rows::Rows;
use crate::server::validate::{answer_within, clip_actions, flat, within};
use crate::server::{ApiError, AppState, Limits, LoadedModel};
use crate::shared::Cancel;

#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
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

impl ScoreRequest {
    /// `actions` (`[batch][candidates]` sequences of `horizon` rows) scored from
    /// `states`, one particle, every other field its default.
    pub fn new(states: Rows, actions: Vec<Vec<Rows>>, horizon: usize) -> Self {
        Self {
            states,
            actions: Some(actions),
            shared_actions: None,
            horizon,
            particles: one(),
            discount: unit(),
            penalty: unit(),
            cvar_alpha: None,
            alpha: None,
            threshold: None,
            seed: 0,
            noise_scale: None,
            clip: yes(),
            cost: None,
        }
    }
}

#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
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
/// diverged. Binary bodies: a safetensors file with `states` `[batch,
/// obs_dim]` and `actions` `[batch, candidates, horizon, act_dim]` or
/// `shared_actions` `[candidates, horizon, act_dim]` (f32), the other fields
/// as string metadata (`cost` as its JSON). With `Accept:
/// application/octet-stream` the answer is a safetensors file of `[batch,
/// candidates]` tensors named as the JSON fields (`cvar_return` NaN when not
/// asked for, `truncated_at` −1 where nothing truncated); `noise_scale` and
/// `clipped_rows` in its metadata. Concurrent requests for the same model
/// share their rollout's model calls (`--batch-delay-us`), each answered as alone.
#[utoipa::path(post, path = "/v1/models/{id}/score", tag = "models",
    params(("id" = String, Path, description = "Model id")),
    request_body(content(
        (ScoreRequest = "application/json"),
        (TensorBytes = "application/octet-stream"),
    )),
    responses(
        (status = 200, description = "Success", content((ScoreResponse = "application/json"), (TensorBytes = "application/octet-stream"))),
        (status = 400, description = "Malformed body", body = crate::server::ErrorBody),
        (status = 404, description = "Unknown model", body = crate::server::ErrorBody),
        (status = 413, body = crate::server::ErrorBody, description = "Body too large"),
        (status = 422, description = "Wrong dimensions, non-finite values, an empty batch, or over a limit", body = crate::server::ErrorBody),
        (status = 503, description = "Timed out or cancelled", body = crate::server::ErrorBody),
    ))]
pub async fn score(
    State(state): State<AppState>,
    Path(id): Path<String>,
    headers: HeaderMap,
    body: RawBody,
) -> Result<Response, ApiError> {
    let model = state.model(&id)?;
    // Said before the body is parsed, so a batch waits for this request.
    let arrival = (state.batcher.enabled()).then(|| state.batcher.arrival());
    let answer = answer_format(&headers);
    let given = match body.format {
        Format::Json => json_request(&body, &model).await?,
        Format::Binary => binary_request(&body, &model)?,
    };
    let (given, config, shape) = checked(given, &model, answer, &state.config.limits)?;
    state
        .metrics
        .batch("score", &id, shape.rows * config.horizon);
    let cancel = Cancel::default();
    // Dropped with this future: on completion (harmless), timeout or hang-up.
    let _cancel_if_abandoned = cancel.on_drop();
    let work = ScoreWork {
        finish: Box::new(answer_scores(id, shape, config.clone(), answer)),
        starts: given.starts,
        sequences: given.sequences,
        per_start: given.per_start,
        config,
        seed: given.request.seed,
        cancel,
    };
    if let Some(arrival) = arrival {
        return state.batcher.run(arrival, model, Work::Score(work)).await;
    }
    state
        .compute(move |cancel| {
            let mut rng = ChaCha8Rng::seed_from_u64(work.seed);
            let candidates = Candidates {
                starts: &work.starts,
                sequences: &work.sequences,
                per_start: work.per_start,
            };
            let dynamics = model.batch_dynamics();
            let scores = score_sequences(
                dynamics,
                &model.rules,
                &candidates,
                &work.config,
                &mut rng,
                cancel,
            );
            (work.finish)(scores)
        })
        .await
}

/// A request as read: its start states and candidates, flat, and the rest.
struct Given {
    starts: Vec<f32>,
    sequences: Vec<f32>,
    per_start: usize,
    request: ScoreRequest,
}

/// The sizes an answer reports.
#[derive(Debug, Clone, Copy)]
struct Shape {
    batch: usize,
    candidates: usize,
    /// batch × candidates × particles: the rollout's rows.
    rows: usize,
    clipped_rows: usize,
}

async fn json_request(body: &RawBody, model: &LoadedModel) -> Result<Given, ApiError> {
    let mut request: ScoreRequest = body.json().await?;
    let batch = request.states.len();
    let starts = std::mem::take(&mut request.states).into_matrix("states", model.obs_dim())?;
    let (sequences, per_start) = candidate_actions(&mut request, model, batch)?;
    Ok(Given {
        starts,
        sequences,
        per_start,
        request,
    })
}

/// The metadata a binary request may carry: the JSON fields but the tensors.
const BINARY_OPTIONS: &[&str] = &[
    "horizon",
    "particles",
    "discount",
    "penalty",
    "cvar_alpha",
    "alpha",
    "threshold",
    "seed",
    "noise_scale",
    "clip",
    "cost",
];

/// A safetensors request: `states`, and `actions` or `shared_actions`
/// (their shape gives the horizon and the candidates), the rest as metadata.
fn binary_request(body: &RawBody, model: &LoadedModel) -> Result<Given, ApiError> {
    let (mut tensors, metadata) = body.tensors()?;
    refuse_unknown_metadata(&metadata, BINARY_OPTIONS)?;
    let obs_dim = model.obs_dim();
    let (shape, starts) = tensors
        .remove("states")
        .ok_or_else(|| ApiError::Invalid("the safetensors body has no `states` tensor".into()))?;
    if shape.len() != 2 || shape[1] != obs_dim {
        return Err(ApiError::Invalid(format!(
            "`states` has shape {shape:?}, this model expects [batch, {obs_dim}]"
        )));
    }
    let batch = flat("states", &starts, obs_dim)?;
    let (sequences, per_start, horizon) = binary_candidates(tensors, batch, model.act_dim())?;
    let given_horizon: usize = metadata_option(&metadata, "horizon", horizon)?;
    if given_horizon != horizon {
        return Err(ApiError::Invalid(format!(
            "metadata `horizon` is {given_horizon} but `actions` has {horizon} steps"
        )));
    }
    Ok(Given {
        starts,
        sequences,
        per_start,
        request: binary_options(&metadata, horizon)?,
    })
}

/// The candidates of a safetensors request, each start's (`actions`) or
/// shared (`shared_actions`, repeated per start), flat; their count per
/// start and their steps.
fn binary_candidates(
    mut tensors: NamedTensors,
    batch: usize,
    act_dim: usize,
) -> Result<(Vec<f32>, usize, usize), ApiError> {
    let (field, (shape, sequences)) =
        match (tensors.remove("actions"), tensors.remove("shared_actions")) {
            (Some(actions), None) => ("actions", actions),
            (None, Some(shared)) => ("shared_actions", shared),
            _ => {
                return Err(ApiError::Invalid(
                    "give an `actions` tensor (per start) or `shared_actions`, exactly one".into(),
                ));
            }
        };
    if let Some(name) = tensors.keys().next() {
        return Err(ApiError::Invalid(format!(
            "the safetensors body has a tensor `{name}`; a score takes `states` and `actions` or `shared_actions`"
        )));
    }
    let (per_start, horizon) = match (field, shape.as_slice()) {
        ("actions", &[b, n, h, a]) if b == batch && a == act_dim => (n, h),
        ("shared_actions", &[n, h, a]) if a == act_dim => (n, h),
        _ => {
            let expected = match field {
                "actions" => format!("[{batch}, candidates, horizon, {act_dim}]"),
                _ => format!("[candidates, horizon, {act_dim}]"),
            };
            return Err(ApiError::Invalid(format!(
                "`{field}` has shape {shape:?}, this model and these states expect {expected}"
            )));
        }
    };
    flat(field, &sequences, act_dim)?;
    let sequences = match field {
        "actions" => sequences,
        _ => sequences.repeat(batch),
    };
    Ok((sequences, per_start, horizon))
}

/// A safetensors request's options, from its metadata (`cost` as its JSON).
fn binary_options(
    metadata: &HashMap<String, String>,
    horizon: usize,
) -> Result<ScoreRequest, ApiError> {
    let optional = |key: &str| -> Result<Option<f64>, ApiError> {
        (metadata.contains_key(key))
            .then(|| metadata_option(metadata, key, 0.0))
            .transpose()
    };
    let cost = match metadata.get("cost") {
        None => None,
        Some(text) => Some(serde_json::from_str(text).map_err(|e| {
            ApiError::Invalid(format!("metadata `cost` is not a cost's JSON: {e}"))
        })?),
    };
    Ok(ScoreRequest {
        states: Rows::default(),
        actions: None,
        shared_actions: None,
        horizon,
        particles: metadata_option(metadata, "particles", 1)?,
        discount: metadata_option(metadata, "discount", 1.0)?,
        penalty: metadata_option(metadata, "penalty", 1.0)?,
        cvar_alpha: optional("cvar_alpha")?,
        alpha: optional("alpha")?,
        threshold: optional("threshold")?.map(|t| t as f32),
        seed: metadata_option(metadata, "seed", 0)?,
        noise_scale: optional("noise_scale")?.map(|n| n as f32),
        clip: metadata_option(metadata, "clip", true)?,
        cost,
    })
}

/// The request's settings checked against the model and the server's limits
/// as the library's scoring; its actions clipped into the action box.
fn checked(
    mut given: Given,
    model: &LoadedModel,
    answer: Format,
    limits: &Limits,
) -> Result<(Given, ScoreConfig, Shape), ApiError> {
    let r = &given.request;
    let batch = given.starts.len() / model.obs_dim();
    within("batch (rows of states)", batch, limits.max_batch)?;
    within("horizon", r.horizon, limits.max_horizon)?;
    within("particles", r.particles, limits.max_particles)?;
    within("candidates", given.per_start, limits.max_batch)?;
    let clipped_rows = clip_actions("actions", &mut given.sequences, &model.action_space, r.clip)?;
    let rows = batch * given.per_start * r.particles;
    within(
        "batch × candidates × particles × horizon",
        rows * r.horizon,
        limits.max_rollout_steps,
    )?;
    // The rollout holds each row's state and running sums, not its trajectory.
    answer_within(
        "batch × candidates × particles × (obs_dim + 8)",
        rows * (model.obs_dim() + 8),
        Format::Binary,
        limits.max_answer_bytes,
    )?;
    answer_within(
        "batch × candidates × 8",
        batch * given.per_start * 8,
        answer,
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
    .config(model)?;
    let shape = Shape {
        batch,
        candidates: given.per_start,
        rows,
        clipped_rows,
    };
    Ok((given, config, shape))
}

/// How a request's scores become its answer (run in the compute work: a
/// large population's JSON takes milliseconds).
fn answer_scores(
    id: String,
    shape: Shape,
    config: ScoreConfig,
    answer: Format,
) -> impl FnOnce(Result<Vec<CandidateScore>, PlanningError>) -> Result<Response, ApiError> + Send + 'static
{
    move |scores| {
        let scores = scores?;
        let (noise_scale, clipped_rows) = (config.noise_scale, shape.clipped_rows);
        if answer == Format::Binary {
            let tensors = binary_scores(&scores, [shape.batch, shape.candidates]);
            return tensors_response(&tensors, noise_scale, clipped_rows);
        }
        json_response(&ScoreResponse {
            model: id,
            batch: shape.batch,
            candidates: shape.candidates,
            horizon: config.horizon,
            particles: config.particles,
            threshold: config.threshold,
            noise_scale,
            clipped_rows,
            scores: scores.chunks(shape.candidates).map(<[_]>::to_vec).collect(),
        })
    }
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
