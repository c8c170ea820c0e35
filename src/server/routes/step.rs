//! `POST /v1/models/{id}/step`: one Euler–Maruyama step for a batch of
//! (state, action) pairs, `particles` samples each. JSON, or safetensors bytes
//! both ways (`application/octet-stream`).

use axum::extract::{Path, State};
use axum::response::Response;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::fields::{integer, one, unit, yes};
use crate::agent::{ParticleConfig, ParticleStep, particle_terms, sample_particles};
use crate::artifact::NamedTensors;
use crate::server::batcher::{StepWork, Work};
use crate::server::body::{
    Format, RawBody, TensorBytes, json_response, metadata_option, refuse_unknown_metadata,
    tensors_response,
};
use crate::server::rows::{Rows, split_rows as rows};
use crate::server::validate::{answer_within, clip_actions, flat, non_negative, within};
use crate::server::{ApiError, AppState};
use crate::shared::ModelStep;

/// A batch of observations and actions to step.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct StepRequest {
    /// Observations, `[batch][obs_dim]` (obs_dim: the model's).
    #[schema(value_type = Vec<Vec<f32>>, min_items = 1)]
    pub states: Rows,
    /// Actions, `[batch][act_dim]` (act_dim: the model's; as many rows as `states`).
    #[schema(value_type = Vec<Vec<f32>>, min_items = 1)]
    pub actions: Rows,
    /// Samples per item (default 1). batch × particles is bounded by the
    /// server's answer budget (`--max-answer-bytes`).
    #[serde(default = "one")]
    #[schema(minimum = 1)]
    #[serde(deserialize_with = "integer")]
    pub particles: usize,
    /// Seed of the noise ε (default 0): the same request gives the same answer.
    #[serde(default)]
    #[serde(deserialize_with = "integer")]
    pub seed: u64,
    /// λ_pen of the penalised reward r − λ_pen·η (default 1).
    #[serde(default = "unit")]
    #[schema(minimum = 0)]
    pub penalty: f64,
    /// Multiplies ε (default: the model's own `sample_noise_scale`, in
    /// `GET /v1/models/{id}`: 1 samples at the calibrated Σ; a model fitted with
    /// NUNO's code's convention samples at sqrt(dt); 0 follows the drift).
    #[serde(default)]
    #[schema(minimum = 0)]
    pub noise_scale: Option<f32>,
    /// Clip actions outside the model's action box into it (default), as
    /// MuJoCo clips controls; false answers 422 for such an action instead.
    #[serde(default = "yes")]
    pub clip: bool,
}

impl StepRequest {
    /// `actions` taken in `states`, one particle, every other field its default.
    pub fn new(states: Rows, actions: Rows) -> Self {
        Self {
            states,
            actions,
            particles: one(),
            seed: 0,
            penalty: unit(),
            noise_scale: None,
            clip: yes(),
        }
    }
}

/// Per item: the SDE's terms; per item and particle: the sampled step.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct StepResponse {
    pub model: String,
    pub batch: usize,
    pub particles: usize,
    /// The scale of ε the samples were drawn at: the request's `noise_scale`,
    /// else the model's own.
    pub noise_scale: f32,
    /// Rows whose action was clipped into the action box.
    pub clipped_rows: usize,
    /// s + f(s, a)·dt, the drift mean: `[batch][obs_dim]`.
    pub mean: Vec<Vec<f32>>,
    /// Aleatoric diffusion σ(s, a): `[batch][obs_dim]`.
    pub sigma: Vec<Vec<f32>>,
    /// Epistemic diffusion h(η(s, a)): `[batch][obs_dim]`.
    pub h_eta: Vec<Vec<f32>>,
    /// Distance-aware uncertainty η(s, a): `[batch]`.
    pub eta: Vec<f32>,
    /// Sampled next observations: `[batch][particles][obs_dim]`.
    pub next_states: Vec<Vec<Vec<f32>>>,
    /// The task's reward (or the learned one for NUNO^R): `[batch][particles]`.
    pub rewards: Vec<Vec<f32>>,
    /// r − λ_pen·η: `[batch][particles]`.
    pub penalized_rewards: Vec<Vec<f32>>,
    /// The task's termination rule on the next observation: `[batch][particles]`.
    pub terminals: Vec<Vec<bool>>,
}

impl StepResponse {
    /// The JSON answer of model `id`'s step `s` (what a binary answer's tensors
    /// hold too, as a client reads them back).
    pub fn from_particles(
        id: &str,
        s: &ParticleStep,
        noise_scale: f32,
        clipped_rows: usize,
    ) -> Self {
        let (p, d) = (s.particles, s.obs_dim);
        Self {
            model: id.to_string(),
            batch: s.batch,
            particles: p,
            noise_scale,
            clipped_rows,
            mean: rows(&s.mean, d),
            sigma: rows(&s.sigma, d),
            h_eta: rows(&s.h_eta, d),
            eta: s.eta.clone(),
            next_states: s
                .next_states
                .chunks(p * d)
                .map(|item| rows(item, d))
                .collect(),
            rewards: rows(&s.rewards, p),
            penalized_rewards: rows(&s.penalized_rewards, p),
            terminals: s.terminals.chunks(p).map(<[bool]>::to_vec).collect(),
        }
    }
}

/// Samples one EM step. Binary bodies: a safetensors file with `states`
/// `[batch, obs_dim]` and `actions` `[batch, act_dim]` (f32), the options as
/// string metadata (`particles`, `seed`, `penalty`, `noise_scale`, `clip`); the answer
/// is a safetensors file (`noise_scale` used and `clipped_rows` in its metadata) with `mean`, `sigma`, `h_eta` `[batch, obs_dim]`,
/// `eta` `[batch]`, `next_states` `[batch, particles, obs_dim]`, `rewards`,
/// `penalized_rewards`, `terminals` (0/1) `[batch, particles]`.
#[utoipa::path(post, path = "/v1/models/{id}/step", tag = "models",
    params(("id" = String, Path, description = "Model id")),
    request_body(content(
        (StepRequest = "application/json"),
        (TensorBytes = "application/octet-stream"),
    )),
    responses(
        (status = 200, description = "Success", content((StepResponse = "application/json"), (TensorBytes = "application/octet-stream"))),
        (status = 400, body = crate::server::ErrorBody, description = "Malformed body"),
        (status = 404, body = crate::server::ErrorBody, description = "Unknown model"),
        (status = 413, body = crate::server::ErrorBody, description = "Body too large"),
        (status = 422, body = crate::server::ErrorBody, description = "Wrong dimensions, non-finite values, empty batch or over a limit"),
    ))]
pub async fn step(
    State(state): State<AppState>,
    Path(id): Path<String>,
    body: RawBody,
) -> Result<Response, ApiError> {
    let model = state.model(&id)?;
    // Said before the body is parsed, so a batch waits for this request.
    let arrival = (state.batcher.enabled()).then(|| state.batcher.arrival());
    let (obs_dim, act_dim) = (model.obs_dim(), model.act_dim());
    let (observations, mut actions, request) = read_request(&body, obs_dim, act_dim).await?;
    let batch = observations.len() / obs_dim;
    let clipped_rows = clip_actions("actions", &mut actions, &model.action_space, request.clip)?;
    let limits = &state.config.limits;
    within("batch (rows of states)", batch, limits.max_batch)?;
    within("particles", request.particles, limits.max_particles)?;
    non_negative("penalty", request.penalty)?;
    let noise_scale = request
        .noise_scale
        .unwrap_or_else(|| model.batch_dynamics().sample_noise_scale());
    non_negative("noise_scale", f64::from(noise_scale))?;
    let rows = batch * request.particles;
    answer_within(
        "batch × (3·obs_dim + 1) + batch × particles × (obs_dim + 3)",
        batch * (3 * obs_dim + 1) + rows * (obs_dim + 3),
        body.format,
        limits.max_answer_bytes,
    )?;
    state.metrics.batch("step", &id, rows);

    let config = ParticleConfig {
        particles: request.particles,
        penalty: request.penalty,
        noise_scale,
    };
    let worker = model.clone();
    let format = body.format;
    // The answer is serialised in the compute work too: at batch 4096 its JSON
    // is megabytes.
    let finish = move |observations: &[f32], actions: &[f32], terms: &ModelStep| {
        let mut rng = ChaCha8Rng::seed_from_u64(request.seed);
        let dynamics = worker.batch_dynamics();
        let items = (observations, actions);
        let result = sample_particles(dynamics, &worker.rules, items, terms, config, &mut rng);
        match format {
            Format::Json => json_response(&StepResponse::from_particles(
                &id,
                &result,
                noise_scale,
                clipped_rows,
            )),
            Format::Binary => tensors_response(&binary_response(result), noise_scale, clipped_rows),
        }
    };
    if let Some(arrival) = arrival {
        let work = Work::Step(StepWork {
            observations,
            actions,
            finish: Box::new(finish),
        });
        return state.batcher.run(arrival, model, work).await;
    }
    state
        .compute(move |_| {
            let terms = particle_terms(model.batch_dynamics(), &observations, &actions);
            finish(&observations, &actions, &terms)
        })
        .await
}

/// The request's states and actions (row-major, of the model's widths and
/// as many rows each) and its options, from either body format.
async fn read_request(
    body: &RawBody,
    obs_dim: usize,
    act_dim: usize,
) -> Result<(Vec<f32>, Vec<f32>, StepRequest), ApiError> {
    let (states, actions, request) = match body.format {
        Format::Json => {
            let mut r: StepRequest = body.json().await?;
            let states = std::mem::take(&mut r.states).into_matrix("states", obs_dim)?;
            let actions = std::mem::take(&mut r.actions).into_matrix("actions", act_dim)?;
            (states, actions, r)
        }
        Format::Binary => binary_request(body, obs_dim, act_dim)?,
    };
    let batch = states.len() / obs_dim;
    if actions.len() / act_dim != batch {
        return Err(ApiError::Invalid(format!(
            "`states` has {batch} rows but `actions` has {}",
            actions.len() / act_dim
        )));
    }
    Ok((states, actions, request))
}

fn binary_request(
    body: &RawBody,
    obs_dim: usize,
    act_dim: usize,
) -> Result<(Vec<f32>, Vec<f32>, StepRequest), ApiError> {
    let (mut tensors, metadata) = body.tensors()?;
    refuse_unknown_metadata(
        &metadata,
        &["particles", "seed", "penalty", "noise_scale", "clip"],
    )?;
    let mut take = |name: &str, width: usize| -> Result<Vec<f32>, ApiError> {
        let (shape, values) = tensors.remove(name).ok_or_else(|| {
            ApiError::Invalid(format!("the safetensors body has no `{name}` tensor"))
        })?;
        if shape.len() != 2 || shape[1] != width {
            return Err(ApiError::Invalid(format!(
                "`{name}` has shape {shape:?}, this model expects [batch, {width}]"
            )));
        }
        flat(name, &values, width)?;
        Ok(values)
    };
    let states = take("states", obs_dim)?;
    let actions = take("actions", act_dim)?;
    let request = StepRequest {
        states: Rows::default(),
        actions: Rows::default(),
        particles: metadata_option(&metadata, "particles", 1)?,
        seed: metadata_option(&metadata, "seed", 0)?,
        penalty: metadata_option(&metadata, "penalty", 1.0)?,
        noise_scale: metadata
            .contains_key("noise_scale")
            .then(|| metadata_option(&metadata, "noise_scale", 1.0))
            .transpose()?,
        clip: metadata_option(&metadata, "clip", true)?,
    };
    Ok((states, actions, request))
}

/// The answer's tensors, moved out of `s` (at the largest accepted batch a
/// copy would be hundreds of MB).
fn binary_response(s: ParticleStep) -> NamedTensors {
    let (b, p, d) = (s.batch, s.particles, s.obs_dim);
    let terminals = s
        .terminals
        .iter()
        .map(|&t| f32::from(u8::from(t)))
        .collect();
    NamedTensors::from([
        ("mean".into(), (vec![b, d], s.mean)),
        ("sigma".into(), (vec![b, d], s.sigma)),
        ("h_eta".into(), (vec![b, d], s.h_eta)),
        ("eta".into(), (vec![b], s.eta)),
        ("next_states".into(), (vec![b, p, d], s.next_states)),
        ("rewards".into(), (vec![b, p], s.rewards)),
        (
            "penalized_rewards".into(),
            (vec![b, p], s.penalized_rewards),
        ),
        ("terminals".into(), (vec![b, p], terminals)),
    ])
}
