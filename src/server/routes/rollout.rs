//! `POST /v1/models/{id}/rollout`: multi-step rollouts from a batch of start
//! states, open loop along given actions or closed loop with the model's
//! policy, with η, accumulated η, penalised rewards, terminal flags and NUNO's
//! truncation at ε(h, α).

use axum::extract::{Path, State};
use axum::http::HeaderMap;
use axum::response::Response;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::fields::{integer, one, unit, yes};
use crate::agent::{
    ActionMode, RolloutActions, RolloutConfig, RolloutTrace, StepOutcome, TruncatedStep,
    penalized_reward, rollout_model_or_cancel,
};
use crate::artifact::NamedTensors;
use crate::sde::requested_threshold;
use crate::server::body::{
    Format, RawBody, TensorBytes, answer_format, json_response, tensors_response,
};
use crate::server::rows::{Rows, split_rows};
use crate::server::validate::{answer_within, clip_actions, non_negative, within};
use crate::server::{ApiError, AppState, Limits, LoadedModel};

#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct RolloutRequest {
    /// Start observations, `[batch][obs_dim]` (obs_dim: the model's).
    #[schema(value_type = Vec<Vec<f32>>, min_items = 1)]
    pub states: Rows,
    /// Open-loop actions `[batch][horizon][act_dim]` (one sequence per start
    /// state, `horizon` steps each, act_dim: the model's); without them the
    /// model's policy acts (409 when it has none).
    #[serde(default)]
    #[schema(value_type = Option<Vec<Vec<Vec<f32>>>>)]
    pub actions: Option<Vec<Rows>>,
    /// Clip open-loop actions outside the model's action box into it
    /// (default), as MuJoCo clips controls; false answers 422 instead.
    #[serde(default = "yes")]
    pub clip: bool,
    /// How the policy acts when it does (default deterministic).
    #[serde(default)]
    pub policy_mode: ActionMode,
    /// Steps h. batch × particles × horizon is bounded by `--max-rollout-steps`
    /// and the answer budget (`--max-answer-bytes`).
    #[schema(minimum = 1)]
    #[serde(deserialize_with = "integer")]
    pub horizon: usize,
    /// Trajectories per start state (default 1).
    #[serde(default = "one")]
    #[schema(minimum = 1)]
    #[serde(deserialize_with = "integer")]
    pub particles: usize,
    #[serde(default)]
    #[serde(deserialize_with = "integer")]
    pub seed: u64,
    /// λ_pen (default 1).
    #[serde(default = "unit")]
    #[schema(minimum = 0)]
    pub penalty: f64,
    /// CVaR level α: truncate at the model's ε(h, α) (h = horizon); the pairs
    /// a model has are in its `thresholds` (`GET /v1/models/{id}`).
    #[serde(default)]
    #[schema(exclusive_minimum = 0, maximum = 1)]
    pub alpha: Option<f64>,
    /// An explicit truncation threshold instead of α (give one of the two).
    #[serde(default)]
    pub threshold: Option<f32>,
    /// Multiplies ε (default: the model's own `sample_noise_scale`, in
    /// `GET /v1/models/{id}`: 1 samples at the calibrated Σ; a model fitted with
    /// NUNO's code's convention samples at sqrt(dt); 0 follows the drift).
    #[serde(default)]
    #[schema(minimum = 0)]
    pub noise_scale: Option<f32>,
}

impl RolloutRequest {
    /// `horizon` steps from `states` with the model's policy, one particle,
    /// every other field its default.
    pub fn new(states: Rows, horizon: usize) -> Self {
        Self {
            states,
            actions: None,
            clip: yes(),
            policy_mode: ActionMode::default(),
            horizon,
            particles: one(),
            seed: 0,
            penalty: unit(),
            alpha: None,
            threshold: None,
            noise_scale: None,
        }
    }
}

/// One trajectory; arrays stop where it ended.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct Trajectory {
    /// Index of its start state in the request.
    pub start: usize,
    pub particle: usize,
    /// The start, then one observation per kept step: `[length + 1][obs_dim]`.
    pub states: Vec<Vec<f32>>,
    /// The action of every step taken, a truncating one included.
    pub actions: Vec<Vec<f32>>,
    /// η(s_k, a_k) of every step taken.
    pub eta: Vec<f32>,
    /// Σ_{j ≤ k} η(s_j, a_j).
    pub accumulated_eta: Vec<f32>,
    /// Rewards before the penalty.
    pub rewards: Vec<f32>,
    /// r − λ_pen·η.
    pub penalized_rewards: Vec<f32>,
    /// Steps kept.
    pub length: usize,
    /// Ended in a terminal state (the task's rules).
    pub terminal: bool,
    /// Accumulated η passed the threshold at step `truncation_step` (that step is not kept).
    pub truncated: bool,
    pub truncation_step: Option<usize>,
    /// The model's next state, reward or η stopped being finite after `length`
    /// steps (its drift diverged off the data); that step is not kept.
    pub diverged: bool,
}

#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct RolloutResponse {
    pub model: String,
    pub horizon: usize,
    pub particles: usize,
    /// The truncation threshold used, if any.
    pub threshold: Option<f32>,
    /// The scale of ε the samples were drawn at: the request's `noise_scale`,
    /// else the model's own.
    pub noise_scale: f32,
    /// Open-loop action rows (start × step) clipped into the action box.
    pub clipped_rows: usize,
    /// Start `b`'s particle `p` is entry `b·particles + p`.
    pub trajectories: Vec<Trajectory>,
}

/// Rolls the model h steps from each start state. With `Accept:
/// application/octet-stream` the answer is a safetensors file instead:
/// `states` `[rows, horizon + 1, obs_dim]`, `actions` `[rows, horizon, act_dim]`,
/// `eta`, `accumulated_eta`, `rewards`, `penalized_rewards` `[rows, horizon]`
/// (NaN past each trajectory's steps taken), `length` `[rows]` (steps kept) and
/// `outcome` `[rows]` (0 ran to h, 1 terminal, 2 truncated, 3 diverged); row
/// `b·particles + p` is start `b`'s particle `p`; `noise_scale` used and `clipped_rows` in its metadata.
#[utoipa::path(post, path = "/v1/models/{id}/rollout", tag = "models",
    params(("id" = String, Path, description = "Model id")),
    request_body = RolloutRequest,
    responses(
        (status = 200, description = "Success", content((RolloutResponse = "application/json"), (TensorBytes = "application/octet-stream"))),
        (status = 400, description = "Malformed body", body = crate::server::ErrorBody),
        (status = 404, description = "Unknown model", body = crate::server::ErrorBody),
        (status = 409, body = crate::server::ErrorBody, description = "No actions given and the model has no policy"),
        (status = 422, description = "Wrong dimensions, non-finite values, an empty batch, or over a limit", body = crate::server::ErrorBody),
    ))]
pub async fn rollout(
    State(state): State<AppState>,
    Path(id): Path<String>,
    headers: HeaderMap,
    body: RawBody,
) -> Result<Response, ApiError> {
    let answer = answer_format(&headers);
    let mut r: RolloutRequest = body.json().await?;
    let model = state.model(&id)?;
    let (obs_dim, act_dim) = (model.obs_dim(), model.act_dim());
    let limits = &state.config.limits;
    let batch = r.states.len();
    within("batch (rows of states)", batch, limits.max_batch)?;
    let starts = std::mem::take(&mut r.states).into_matrix("states", obs_dim)?;
    check_size(&r, batch, (obs_dim, act_dim), answer, limits)?;
    let noise_scale = r
        .noise_scale
        .unwrap_or_else(|| model.batch_dynamics().sample_noise_scale());
    non_negative("noise_scale", f64::from(noise_scale))?;
    let (sequence, clipped_rows) = open_loop_actions(&mut r, &model, batch)?;
    let threshold = resolve_threshold(r.threshold, r.alpha, r.horizon, &model)?;
    state
        .metrics
        .batch("rollout", &id, batch * r.particles * r.horizon);

    let config = served_rollout(&r, threshold, noise_scale);
    let (seed, mode) = (r.seed, r.policy_mode);
    let worker = model.clone();
    // The trajectories are built and serialised in the compute work too: at
    // 4096 starts × 10 steps the JSON answer is megabytes.
    state
        .compute(move |cancel| {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let policy = worker.batch_policy(mode);
            let source = match (&sequence, &policy) {
                (Some(actions), _) => RolloutActions::Sequence(actions),
                (None, Some(policy)) => RolloutActions::Policy(policy.as_ref()),
                (None, None) => return Err(ApiError::NoPolicy(worker.id.clone())),
            };
            let out = rollout_model_or_cancel(
                worker.batch_dynamics(),
                source,
                &worker.rules,
                &starts,
                &config,
                &mut rng,
                cancel,
            )?;
            if answer == Format::Binary {
                return tensors_response(
                    &binary_rollout(&out.trace, r.penalty, (obs_dim, act_dim)),
                    noise_scale,
                    clipped_rows,
                );
            }
            json_response(&RolloutResponse {
                model: id,
                horizon: r.horizon,
                particles: r.particles,
                threshold,
                noise_scale,
                clipped_rows,
                trajectories: trajectories(&out.trace, r.penalty, r.particles, (obs_dim, act_dim)),
            })
        })
        .await
}

/// The rollout a request asks for: its horizon, particles, λ and ε, the
/// model's own noise scale unless it gives one; the truncating step dropped, as
/// the paper does, and none of the training loop's guards (HALT, state box,
/// clipping): the server answers what the model does.
fn served_rollout(r: &RolloutRequest, threshold: Option<f32>, noise_scale: f32) -> RolloutConfig {
    RolloutConfig {
        horizon: r.horizon,
        particles: r.particles,
        penalty: r.penalty,
        threshold,
        noise_scale,
        halt: None,
        state_box: None,
        observation_clip: None,
        truncated_step: TruncatedStep::Drop,
    }
}

/// The request's horizon, particles, penalty and the size of its work and
/// answer against the server's limits.
fn check_size(
    r: &RolloutRequest,
    batch: usize,
    (obs_dim, act_dim): (usize, usize),
    answer: Format,
    limits: &Limits,
) -> Result<(), ApiError> {
    within("horizon", r.horizon, limits.max_horizon)?;
    within("particles", r.particles, limits.max_particles)?;
    within(
        "batch × particles × horizon",
        batch * r.particles * r.horizon,
        limits.max_rollout_steps,
    )?;
    non_negative("penalty", r.penalty)?;
    answer_within(
        "batch × particles × ((horizon + 1)·obs_dim + horizon·(act_dim + 4) + 2)",
        batch * r.particles * ((r.horizon + 1) * obs_dim + r.horizon * (act_dim + 4) + 2),
        answer,
        limits.max_answer_bytes,
    )
}

/// The request's open-loop actions, flat and clipped into the model's action
/// box, with how many rows were clipped; none where the model's policy acts
/// (a policy's actions are in the box by construction: tanh, scaled).
fn open_loop_actions(
    r: &mut RolloutRequest,
    model: &LoadedModel,
    batch: usize,
) -> Result<(Option<Vec<f32>>, usize), ApiError> {
    let Some(actions) = r.actions.take() else {
        return match model.policy {
            None => Err(ApiError::NoPolicy(model.id.clone())),
            Some(_) => Ok((None, 0)),
        };
    };
    let mut flat = flatten_sequences(actions, batch, r.horizon, model.act_dim())?;
    let clipped = clip_actions("actions", &mut flat, &model.action_space, r.clip)?;
    Ok((Some(flat), clipped))
}

/// One open-loop sequence per start, `horizon` rows of `act_dim` each, as one
/// row-major buffer `[batch · horizon · act_dim]`.
fn flatten_sequences(
    actions: Vec<Rows>,
    batch: usize,
    horizon: usize,
    act_dim: usize,
) -> Result<Vec<f32>, ApiError> {
    if actions.len() != batch {
        return Err(ApiError::Invalid(format!(
            "`actions` has {} sequences for {batch} start states",
            actions.len()
        )));
    }
    let mut flat = Vec::with_capacity(batch * horizon * act_dim);
    for (b, sequence) in actions.into_iter().enumerate() {
        if sequence.len() != horizon {
            return Err(ApiError::Invalid(format!(
                "`actions[{b}]` has {} steps, the horizon is {horizon}",
                sequence.len()
            )));
        }
        flat.extend(sequence.into_matrix(&format!("actions[{b}]"), act_dim)?);
    }
    Ok(flat)
}

/// The request's truncation threshold: `threshold`, or ε(h, α) from the
/// model's table.
pub(super) fn resolve_threshold(
    threshold: Option<f32>,
    alpha: Option<f64>,
    horizon: usize,
    model: &LoadedModel,
) -> Result<Option<f32>, ApiError> {
    requested_threshold(model.thresholds(), threshold, alpha, horizon)
        .map_err(|e| ApiError::Invalid(e.to_string()))
}

/// The trace's rows as JSON trajectories, start and particle named.
fn trajectories(
    t: &RolloutTrace,
    penalty: f64,
    particles: usize,
    (obs_dim, act_dim): (usize, usize),
) -> Vec<Trajectory> {
    (0..t.rows)
        .map(|row| {
            let truncated = t.outcome[row] == StepOutcome::Truncated;
            Trajectory {
                start: row / particles,
                particle: row % particles,
                states: split_rows(&t.observations[row], obs_dim),
                actions: split_rows(&t.actions[row], act_dim),
                eta: t.eta[row].clone(),
                accumulated_eta: t.accumulated_eta[row].clone(),
                rewards: t.rewards[row].clone(),
                penalized_rewards: t.rewards[row]
                    .iter()
                    .zip(&t.eta[row])
                    .map(|(&reward, &eta)| penalized_reward(reward, penalty, eta))
                    .collect(),
                length: t.kept[row],
                terminal: t.outcome[row] == StepOutcome::Terminal,
                truncated,
                truncation_step: truncated.then_some(t.kept[row]),
                diverged: t.outcome[row] == StepOutcome::Diverged,
            }
        })
        .collect()
}

/// The trace as padded tensors (see [`rollout`]'s description).
fn binary_rollout(
    t: &RolloutTrace,
    penalty: f64,
    (obs_dim, act_dim): (usize, usize),
) -> NamedTensors {
    let (rows, h) = (t.rows, t.horizon);
    let padded = |per_row: &[Vec<f32>], width: usize, steps: usize| -> Vec<f32> {
        let mut out = vec![f32::NAN; rows * steps * width];
        for (row, values) in per_row.iter().enumerate() {
            out[row * steps * width..][..values.len()].copy_from_slice(values);
        }
        out
    };
    let penalized: Vec<Vec<f32>> = t
        .rewards
        .iter()
        .zip(&t.eta)
        .map(|(rewards, eta)| {
            rewards
                .iter()
                .zip(eta)
                .map(|(&reward, &eta)| penalized_reward(reward, penalty, eta))
                .collect()
        })
        .collect();
    let outcome = t
        .outcome
        .iter()
        .map(|o| match o {
            StepOutcome::Continued => 0.0,
            // The server's rollouts never halt (MOReL's HALT is a training rule).
            StepOutcome::Terminal | StepOutcome::Halted => 1.0,
            StepOutcome::Truncated => 2.0,
            StepOutcome::Diverged => 3.0,
        })
        .collect();
    NamedTensors::from([
        (
            "states".into(),
            (
                vec![rows, h + 1, obs_dim],
                padded(&t.observations, obs_dim, h + 1),
            ),
        ),
        (
            "actions".into(),
            (vec![rows, h, act_dim], padded(&t.actions, act_dim, h)),
        ),
        ("eta".into(), (vec![rows, h], padded(&t.eta, 1, h))),
        (
            "accumulated_eta".into(),
            (vec![rows, h], padded(&t.accumulated_eta, 1, h)),
        ),
        ("rewards".into(), (vec![rows, h], padded(&t.rewards, 1, h))),
        (
            "penalized_rewards".into(),
            (vec![rows, h], padded(&penalized, 1, h)),
        ),
        (
            "length".into(),
            (vec![rows], t.kept.iter().map(|&k| k as f32).collect()),
        ),
        ("outcome".into(), (vec![rows], outcome)),
    ])
}
