//! What `score` and `plan` requests share: their scoring settings, checked
//! against the model and the server's limits in one place, and the caller's
//! cost terms on named observations.

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::fields::integer;
use super::rollout::resolve_threshold;
use crate::planning::{Cost, CostTerm, ScoreConfig};
use crate::server::validate::non_negative;
use crate::server::{ApiError, LoadedModel};

/// A request's quadratic costs on the observations its candidates reach.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CostRequest {
    /// Each kept step's reward becomes r − Σ weight·(s′[observation] − target)².
    #[schema(min_items = 1)]
    pub terms: Vec<CostTermRequest>,
    /// Score on the costs alone: −Σ weight·(s′ − target)², the model's reward left out.
    #[serde(default)]
    pub replace_reward: bool,
}

#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CostTermRequest {
    /// The observation: its name in the model's system file, or its 0-based index.
    pub observation: ObservationRef,
    pub target: f32,
    /// Its weight (default 1).
    #[serde(default = "unit_weight")]
    #[schema(minimum = 0)]
    pub weight: f32,
}

/// An observation by name or by index.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
#[serde(untagged)]
pub enum ObservationRef {
    Name(String),
    Index(#[serde(deserialize_with = "integer")] u64),
}

fn unit_weight() -> f32 {
    1.0
}

/// The scoring settings of a request, as given.
pub(super) struct ScoringFields<'a> {
    pub horizon: usize,
    pub particles: usize,
    pub discount: f64,
    pub penalty: f64,
    pub cvar_alpha: Option<f64>,
    pub alpha: Option<f64>,
    pub threshold: Option<f32>,
    pub noise_scale: Option<f32>,
    pub cost: Option<&'a CostRequest>,
}

impl ScoringFields<'_> {
    /// The library's scoring: the model's noise scale and ε(H, α) where the
    /// request leaves them out, cost terms resolved to observation indices.
    pub fn config(&self, model: &LoadedModel) -> Result<ScoreConfig, ApiError> {
        non_negative("penalty", self.penalty)?;
        let noise_scale =
            (self.noise_scale).unwrap_or_else(|| model.batch_dynamics().sample_noise_scale());
        non_negative("noise_scale", f64::from(noise_scale))?;
        Ok(ScoreConfig {
            horizon: self.horizon,
            particles: self.particles,
            discount: self.discount,
            penalty: self.penalty,
            cvar_alpha: self.cvar_alpha,
            threshold: resolve_threshold(self.threshold, self.alpha, self.horizon, model)?,
            noise_scale,
            cost: self
                .cost
                .map(|c| cost(c, model))
                .transpose()?
                .unwrap_or_default(),
        })
    }
}

fn cost(request: &CostRequest, model: &LoadedModel) -> Result<Cost, ApiError> {
    if request.terms.is_empty() {
        return Err(ApiError::Invalid(
            "`cost.terms` is empty: give at least one term, or leave `cost` out".into(),
        ));
    }
    let names = model.system.observation_names();
    let terms = (request.terms.iter().enumerate())
        .map(|(i, term)| {
            let dimension = match &term.observation {
                ObservationRef::Index(k) => usize::try_from(*k).unwrap_or(usize::MAX),
                ObservationRef::Name(name) => match names {
                    None => Err(ApiError::Invalid(format!(
                        "`cost.terms[{i}].observation`: `{}`'s observations have no names; give the index",
                        model.system.name()
                    )))?,
                    Some(names) => names.iter().position(|n| n == name).ok_or_else(|| {
                        ApiError::Invalid(format!(
                            "`cost.terms[{i}].observation`: no observation `{name}` (the model's are {})",
                            names.join(", ")
                        ))
                    })?,
                },
            };
            Ok(CostTerm {
                dimension,
                target: term.target,
                weight: term.weight,
            })
        })
        .collect::<Result<_, ApiError>>()?;
    Ok(Cost {
        terms,
        replace_reward: request.replace_reward,
    })
}
