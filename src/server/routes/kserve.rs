//! The KServe Open Inference Protocol v2 for `step`, so generic inference
//! clients work: health, server and model metadata, readiness, and `infer`
//! with inputs `states` and `actions` (FP32, `[batch, dim]`, flat `data`).
//! Errors follow the protocol: `{ "error": "<message>" }`.

use axum::Json;
use axum::extract::{Path, State};
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use crate::agent::{ParticleConfig, step_particles};
use crate::server::body::RawBody;
use crate::server::validate::{flat, within};
use crate::server::{ApiError, AppState};

/// v2's error shape.
pub struct V2Error(ApiError);

impl From<ApiError> for V2Error {
    fn from(e: ApiError) -> Self {
        Self(e)
    }
}

impl IntoResponse for V2Error {
    fn into_response(self) -> Response {
        let (status, _) = self.0.status_code();
        (
            status,
            Json(serde_json::json!({ "error": self.0.client_message() })),
        )
            .into_response()
    }
}

pub async fn live() -> Json<serde_json::Value> {
    Json(serde_json::json!({ "live": true }))
}

pub async fn ready(State(state): State<AppState>) -> Response {
    let ready = !state.registry.snapshot().is_empty();
    let status = if ready {
        StatusCode::OK
    } else {
        StatusCode::SERVICE_UNAVAILABLE
    };
    (status, Json(serde_json::json!({ "ready": ready }))).into_response()
}

pub async fn server_metadata() -> Json<serde_json::Value> {
    Json(serde_json::json!({
        "name": "nuno",
        "version": env!("CARGO_PKG_VERSION"),
        "extensions": [],
    }))
}

pub async fn model_ready(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Json<serde_json::Value>, V2Error> {
    let model = state.model(&id)?;
    Ok(Json(serde_json::json!({ "name": model.id, "ready": true })))
}

/// A tensor's name, datatype and shape (-1: any batch).
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct V2TensorMetadata {
    pub name: String,
    pub datatype: String,
    pub shape: Vec<i64>,
}

#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct V2ModelMetadata {
    pub name: String,
    pub versions: Vec<String>,
    pub platform: String,
    pub inputs: Vec<V2TensorMetadata>,
    pub outputs: Vec<V2TensorMetadata>,
}

fn tensor(name: &str, datatype: &str, shape: Vec<i64>) -> V2TensorMetadata {
    V2TensorMetadata {
        name: name.into(),
        datatype: datatype.into(),
        shape,
    }
}

/// v2 model metadata of the `step` operation.
#[utoipa::path(get, path = "/v2/models/{id}", tag = "kserve-v2",
    params(("id" = String, Path, description = "Model id")),
    responses((status = 200, description = "Success", body = V2ModelMetadata), (status = 404, description = "Unknown model")))]
pub async fn v2_model_metadata(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Json<V2ModelMetadata>, V2Error> {
    let model = state.model(&id)?;
    let (d, a) = (
        model.metadata.spec.obs_dim as i64,
        model.metadata.spec.act_dim as i64,
    );
    Ok(Json(V2ModelMetadata {
        name: model.id.clone(),
        versions: vec!["1".into()],
        platform: "nuno-neural-sde".into(),
        inputs: vec![
            tensor("states", "FP32", vec![-1, d]),
            tensor("actions", "FP32", vec![-1, a]),
        ],
        outputs: vec![
            tensor("next_states", "FP32", vec![-1, d]),
            tensor("mean", "FP32", vec![-1, d]),
            tensor("sigma", "FP32", vec![-1, d]),
            tensor("h_eta", "FP32", vec![-1, d]),
            tensor("eta", "FP32", vec![-1]),
            tensor("rewards", "FP32", vec![-1]),
            tensor("penalized_rewards", "FP32", vec![-1]),
            tensor("terminals", "BOOL", vec![-1]),
        ],
    }))
}

/// One v2 tensor with its data flattened row-major.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct InferTensor {
    pub name: String,
    pub shape: Vec<usize>,
    pub datatype: String,
    #[schema(value_type = Vec<f64>)]
    pub data: serde_json::Value,
}

#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct InferRequest {
    #[serde(default)]
    pub id: Option<String>,
    pub inputs: Vec<InferTensor>,
    /// `seed`, `penalty`, `noise_scale` (one particle per row).
    #[serde(default)]
    #[schema(value_type = Object)]
    pub parameters: serde_json::Map<String, serde_json::Value>,
}

#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct InferResponse {
    pub model_name: String,
    pub model_version: String,
    pub id: Option<String>,
    pub outputs: Vec<InferTensor>,
}

/// One EM step per row, in the v2 inference format.
#[utoipa::path(post, path = "/v2/models/{id}/infer", tag = "kserve-v2",
    params(("id" = String, Path, description = "Model id")),
    request_body = InferRequest,
    responses((status = 200, description = "Success", body = InferResponse), (status = 400, description = "Malformed"), (status = 404, description = "Unknown model")))]
pub async fn infer(
    State(state): State<AppState>,
    Path(id): Path<String>,
    body: RawBody,
) -> Result<Json<InferResponse>, V2Error> {
    let r: InferRequest = body.json().await?;
    let model = state.model(&id)?;
    let spec = &model.metadata.spec;
    let input = |name: &str, width: usize| -> Result<Vec<f32>, ApiError> {
        let t = r
            .inputs
            .iter()
            .find(|t| t.name == name)
            .ok_or_else(|| ApiError::Invalid(format!("input `{name}` is missing")))?;
        if t.datatype != "FP32" {
            return Err(ApiError::Invalid(format!(
                "input `{name}` must be FP32, got {}",
                t.datatype
            )));
        }
        let values: Vec<f32> = serde_json::from_value::<Vec<f64>>(t.data.clone())
            .map_err(|e| ApiError::Invalid(format!("input `{name}` data: {e}")))?
            .into_iter()
            .map(|v| v as f32)
            .collect();
        let rows = flat(name, &values, width)?;
        if t.shape != [rows, width] {
            return Err(ApiError::Invalid(format!(
                "input `{name}` has shape {:?} but {} values; expected [{rows}, {width}]",
                t.shape,
                values.len()
            )));
        }
        Ok(values)
    };
    let states = input("states", spec.obs_dim)?;
    let actions = input("actions", spec.act_dim)?;
    let batch = states.len() / spec.obs_dim;
    if actions.len() / spec.act_dim != batch {
        return Err(ApiError::Invalid("`states` and `actions` differ in rows".into()).into());
    }
    within("batch", batch, state.config.limits.max_batch)?;
    let number = |key: &str, default: f64| -> Result<f64, ApiError> {
        match r.parameters.get(key) {
            None => Ok(default),
            Some(v) => v
                .as_f64()
                .filter(|x| x.is_finite() && *x >= 0.0)
                .ok_or_else(|| {
                    ApiError::Invalid(format!("parameter `{key}` must be a number ≥ 0"))
                }),
        }
    };
    let seed = number("seed", 0.0)? as u64;
    let config = ParticleConfig {
        particles: 1,
        penalty: number("penalty", 1.0)?,
        noise_scale: number("noise_scale", 1.0)? as f32,
    };
    state.metrics.batch("infer", &id, batch);
    let worker = model.clone();
    let s = state
        .compute(move |_| {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            Ok(step_particles(
                worker.batch_dynamics(),
                &worker.rules,
                &states,
                &actions,
                config,
                &mut rng,
            ))
        })
        .await?;
    let d = s.obs_dim;
    let fp32 = |name: &str, shape: Vec<usize>, data: &[f32]| InferTensor {
        name: name.into(),
        shape,
        datatype: "FP32".into(),
        data: serde_json::json!(data),
    };
    Ok(Json(InferResponse {
        model_name: id,
        model_version: "1".into(),
        id: r.id,
        outputs: vec![
            fp32("next_states", vec![batch, d], &s.next_states),
            fp32("mean", vec![batch, d], &s.mean),
            fp32("sigma", vec![batch, d], &s.sigma),
            fp32("h_eta", vec![batch, d], &s.h_eta),
            fp32("eta", vec![batch], &s.eta),
            fp32("rewards", vec![batch], &s.rewards),
            fp32("penalized_rewards", vec![batch], &s.penalized_rewards),
            InferTensor {
                name: "terminals".into(),
                shape: vec![batch],
                datatype: "BOOL".into(),
                data: serde_json::json!(s.terminals),
            },
        ],
    }))
}
