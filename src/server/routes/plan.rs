//! `POST /v1/models/{id}/plan`: one control step of a sampling planner (MPPI,
//! CEM or iCEM) run in the model from one state, η-aware through the scores it
//! maximises; an optional session keeps the plan so the next step
//! warm-starts from it.

use std::time::Instant;

use axum::extract::{Path, State};
use axum::response::Response;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::fields::{integer, one, optional_integer, unit};
use super::scoring::{CostRequest, ScoringFields};
use crate::planning::{CandidateScore, PlanConfig, PlanStart, Planner, PlannerSettings, plan};
use crate::server::body::{RawBody, json_response};
use crate::server::plan_sessions::{KeptPlan, PlanSessions};
use crate::server::validate::within;
use crate::server::{ApiError, AppState};

#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct PlanRequest {
    /// The state to plan from, `[obs_dim]` (the model's).
    pub state: Vec<f32>,
    pub planner: Planner,
    /// Steps H of the plan.
    #[schema(minimum = 1)]
    #[serde(deserialize_with = "integer")]
    pub horizon: usize,
    /// Candidates sampled per iteration.
    #[schema(minimum = 1)]
    #[serde(deserialize_with = "integer")]
    pub population: usize,
    #[schema(minimum = 1)]
    #[serde(deserialize_with = "integer")]
    pub iterations: usize,
    /// Samples of each candidate (default 1).
    #[serde(default = "one")]
    #[schema(minimum = 1)]
    #[serde(deserialize_with = "integer")]
    pub particles: usize,
    /// MPPI: weights exp((R − max R)/temperature) (default 1).
    #[serde(default)]
    #[schema(exclusive_minimum = 0)]
    pub temperature: Option<f64>,
    /// MPPI: β of the smoothed noise (default 0.9, mbrl-lib's).
    #[serde(default)]
    #[schema(exclusive_minimum = 0, maximum = 1)]
    pub smoothing: Option<f64>,
    /// CEM and iCEM: the candidates each iteration refits to (default
    /// ⌈population / 10⌉; at most the population, which more elites mean).
    #[serde(default, deserialize_with = "optional_integer")]
    #[schema(minimum = 1)]
    pub elites: Option<usize>,
    /// CEM and iCEM: the share of the old distribution kept per refit (default 0.1).
    #[serde(default)]
    #[schema(minimum = 0, exclusive_maximum = 1)]
    pub momentum: Option<f64>,
    /// iCEM: iteration i samples ⌈population·decay^(−i)⌉, at least 2·elites (default 1.3).
    #[serde(default)]
    #[schema(minimum = 1)]
    pub decay: Option<f64>,
    /// iCEM: the exponent β of the samples' power spectrum f^(−β) along
    /// time (default 2: smooth; 0: white, as CEM).
    #[serde(default)]
    #[schema(minimum = 0)]
    pub colored_noise: Option<f64>,
    /// iCEM: the share of elites carried to the next iteration and, with a
    /// session, the next call (default 0.3).
    #[serde(default)]
    #[schema(minimum = 0, maximum = 1)]
    pub keep_elites: Option<f64>,
    /// Sampling spread as a share of each action's half-range (default: CEM and iCEM 0.5, MPPI 1).
    #[serde(default)]
    #[schema(exclusive_minimum = 0)]
    pub noise: Option<f64>,
    /// γ of the returns (default 1).
    #[serde(default = "unit")]
    #[schema(exclusive_minimum = 0, maximum = 1)]
    pub discount: f64,
    /// λ on η: candidates maximise Σ γ^t (r_t − λ·η_t) (default 1).
    #[serde(default = "unit")]
    #[schema(minimum = 0)]
    pub penalty: f64,
    /// Risk: maximise the CVaR of the return over this share of particles,
    /// worst first, less λ·(mean accumulated η).
    #[serde(default)]
    #[schema(exclusive_minimum = 0, maximum = 1)]
    pub cvar_alpha: Option<f64>,
    /// CVaR level α of the truncation ε(H, α); or give `threshold`.
    #[serde(default)]
    #[schema(exclusive_minimum = 0, maximum = 1)]
    pub alpha: Option<f64>,
    #[serde(default)]
    pub threshold: Option<f32>,
    #[serde(default)]
    #[serde(deserialize_with = "integer")]
    pub seed: u64,
    /// Multiplies ε (default: the model's own `sample_noise_scale`).
    #[serde(default)]
    #[schema(minimum = 0)]
    pub noise_scale: Option<f32>,
    /// Continue this session: warm-start from its last plan, shifted one step.
    #[serde(default)]
    pub session: Option<String>,
    /// Open a session, named in the answer, that keeps this plan.
    #[serde(default)]
    pub open_session: bool,
    /// Your own costs on the observations reached, added to the reward or
    /// replacing it (a target for a joint, a position to reach).
    #[serde(default)]
    pub cost: Option<CostRequest>,
}

impl PlanRequest {
    /// `planner` over `horizon` steps from `state`, `population` candidates and
    /// `iterations` rounds, one particle, every other field its default.
    pub fn new(
        state: Vec<f32>,
        planner: Planner,
        horizon: usize,
        population: usize,
        iterations: usize,
    ) -> Self {
        Self {
            state,
            planner,
            horizon,
            population,
            iterations,
            particles: one(),
            temperature: None,
            smoothing: None,
            elites: None,
            momentum: None,
            decay: None,
            colored_noise: None,
            keep_elites: None,
            noise: None,
            discount: unit(),
            penalty: unit(),
            cvar_alpha: None,
            alpha: None,
            threshold: None,
            seed: 0,
            noise_scale: None,
            session: None,
            open_session: false,
            cost: None,
        }
    }
}

#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct PlanResponse {
    pub model: String,
    pub planner: Planner,
    /// `[horizon][act_dim]`: the plan; its first row is the action to take now.
    pub actions: Vec<Vec<f32>>,
    pub first_action: Vec<f32>,
    /// The plan scored once more after the last iteration.
    pub score: CandidateScore,
    /// What the planner maximised, for the plan.
    pub objective: f64,
    /// The session that keeps this plan, if any.
    pub session: Option<String>,
    /// Whether the search started from the session's last plan.
    pub warm_started: bool,
    /// Seconds the planning took, queueing for a compute slot excluded.
    pub seconds: f64,
}

/// Plans `horizon` actions from `state` with MPPI, CEM or iCEM over the model's
/// η-penalised (or CVaR) returns, mbrl-lib's planners (docs/paper-map.md).
/// With `open_session` the plan is kept under a new session id; with
/// `session` the search starts from that session's last plan shifted one
/// step (iCEM also from its last elites), and the new plan replaces it. An unknown or expired session is a 404.
#[utoipa::path(post, path = "/v1/models/{id}/plan", tag = "models",
    params(("id" = String, Path, description = "Model id")),
    request_body = PlanRequest,
    responses(
        (status = 200, description = "Success", body = PlanResponse),
        (status = 400, description = "Malformed body", body = crate::server::ErrorBody),
        (status = 404, description = "Unknown model, or an unknown or expired session", body = crate::server::ErrorBody),
        (status = 422, description = "Wrong dimensions, a setting out of range, or over a limit", body = crate::server::ErrorBody),
        (status = 503, description = "Timed out or cancelled", body = crate::server::ErrorBody),
    ))]
pub async fn plan_route(
    State(state): State<AppState>,
    Path(id): Path<String>,
    body: RawBody,
) -> Result<Response, ApiError> {
    let arrived = Instant::now();
    let r: PlanRequest = body.json().await?;
    let model = state.model(&id)?;
    let config = plan_config(&r, &state, &model)?;
    let start = checked_state(&r.state, model.obs_dim())?;
    let sessions = state.plan_sessions.clone();
    let session = session_name(&r)?;
    let warm = match &r.session {
        Some(name) => Some(sessions.warm(name, &id, r.horizon, arrived)?),
        None => None,
    };
    let population = config.population * config.score.particles * config.score.horizon;
    state
        .metrics
        .batch("plan", &id, population * config.iterations);
    state
        .compute(move |cancel| {
            let began = Instant::now();
            let mut rng = ChaCha8Rng::seed_from_u64(r.seed);
            let from = PlanStart {
                state: &start,
                action_box: &model.action_space,
                warm: warm.as_ref().map(|w| w.actions.as_slice()),
                elites: warm.as_ref().map_or(&[], |w| w.elites.as_slice()),
            };
            let found = plan(
                model.batch_dynamics(),
                &model.rules,
                &from,
                &config,
                &mut rng,
                cancel,
            )?;
            if let Some(name) = &session {
                let kept = KeptPlan {
                    actions: found.actions.clone(),
                    elites: found.elites,
                };
                sessions.keep(name, &id, r.horizon, kept, Instant::now());
            }
            let act_dim = model.act_dim();
            json_response(&PlanResponse {
                model: id,
                planner: r.planner,
                first_action: found.actions[..act_dim].to_vec(),
                actions: found.actions.chunks(act_dim).map(<[_]>::to_vec).collect(),
                score: found.score,
                objective: found.objective,
                session,
                warm_started: warm.is_some(),
                seconds: began.elapsed().as_secs_f64(),
            })
        })
        .await
}

/// The session this plan is kept in: the one it continues, a new one it
/// opens, or none.
fn session_name(r: &PlanRequest) -> Result<Option<String>, ApiError> {
    match (&r.session, r.open_session) {
        (Some(_), true) => Err(ApiError::Invalid(
            "give `session` (continue one) or `open_session` (start one), not both".into(),
        )),
        (Some(name), false) => Ok(Some(name.clone())),
        (None, true) => Ok(Some(PlanSessions::new_id())),
        (None, false) => Ok(None),
    }
}

/// The request's planner and scoring, with the defaults filled and the
/// server's limits applied.
fn plan_config(
    r: &PlanRequest,
    state: &AppState,
    model: &crate::server::LoadedModel,
) -> Result<PlanConfig, ApiError> {
    let limits = &state.config.limits;
    within("horizon", r.horizon, limits.max_horizon)?;
    within("particles", r.particles, limits.max_particles)?;
    within("population", r.population, limits.max_batch)?;
    within(
        "population × particles × horizon",
        r.population * r.particles * r.horizon,
        limits.max_rollout_steps,
    )?;
    within("iterations", r.iterations, limits.max_plan_iterations)?;
    let settings = PlannerSettings {
        temperature: r.temperature,
        smoothing: r.smoothing,
        elites: r.elites,
        momentum: r.momentum,
        decay: r.decay,
        colored_noise: r.colored_noise,
        keep_elites: r.keep_elites,
        noise: r.noise,
    };
    let (optimizer, noise) = r.planner.configure(&settings, r.population)?;
    let score = ScoringFields {
        horizon: r.horizon,
        particles: r.particles,
        discount: r.discount,
        penalty: r.penalty,
        cvar_alpha: r.cvar_alpha,
        alpha: r.alpha,
        threshold: r.threshold,
        noise_scale: r.noise_scale,
        cost: r.cost.as_ref(),
    };
    Ok(PlanConfig {
        optimizer,
        population: r.population,
        iterations: r.iterations,
        noise,
        score: score.config(model)?,
    })
}

/// The state, `obs_dim` finite values.
fn checked_state(state: &[f32], obs_dim: usize) -> Result<Vec<f32>, ApiError> {
    if state.len() != obs_dim {
        return Err(ApiError::Invalid(format!(
            "`state` has {} values, the model's observations {obs_dim}",
            state.len()
        )));
    }
    if let Some(i) = state.iter().position(|v| !v.is_finite()) {
        return Err(ApiError::Invalid(format!(
            "`state[{i}]` is not a finite number"
        )));
    }
    Ok(state.to_vec())
}
