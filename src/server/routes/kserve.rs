//! The KServe Open Inference Protocol v2 for `step`, so generic inference
//! clients work: health, server and model metadata, readiness, and `infer`
//! with inputs `states` and `actions` (FP32, `[batch, dim]`, flat `data` or
//! the binary tensor extension, `kserve_binary`).
//! Errors follow the protocol: `{ "error": "<message>" }`.

use axum::Json;
use axum::extract::{Path, State};
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::fields::integers;
use super::kserve_binary::{OutputData, binary_response, binary_size, decode_fp32};
use crate::agent::{ParticleConfig, ParticleStep, step_particles};
use crate::server::body::{Format, INFERENCE_HEADER_LENGTH, RawBody, TensorBytes, json_response};
use crate::server::validate::{clip_actions, flat, within};
use crate::server::{ApiError, AppState, LoadedModel};

/// v2's error shape.
pub struct V2Error(ApiError);

impl From<ApiError> for V2Error {
    fn from(e: ApiError) -> Self {
        Self(e)
    }
}

impl IntoResponse for V2Error {
    fn into_response(self) -> Response {
        self.0.into_v2_response()
    }
}

/// KServe v2 liveness: the process answers.
#[utoipa::path(get, path = "/v2/health/live", tag = "kserve-v2", security(()),
    responses((status = 200, description = "Live", body = Object)))]
pub async fn live() -> Json<serde_json::Value> {
    Json(serde_json::json!({ "live": true }))
}

/// KServe v2 readiness: at least one model is loaded.
#[utoipa::path(get, path = "/v2/health/ready", tag = "kserve-v2", security(()),
    responses((status = 200, description = "Ready", body = Object), (status = 503, description = "No model loaded", body = Object)))]
pub async fn ready(State(state): State<AppState>) -> Response {
    let ready = !state.registry.snapshot().is_empty();
    let status = if ready {
        StatusCode::OK
    } else {
        StatusCode::SERVICE_UNAVAILABLE
    };
    (status, Json(serde_json::json!({ "ready": ready }))).into_response()
}

/// KServe v2 server metadata: name, version, protocol extensions.
#[utoipa::path(get, path = "/v2", tag = "kserve-v2",
    responses((status = 200, description = "Success", body = Object)))]
pub async fn server_metadata() -> Json<serde_json::Value> {
    Json(serde_json::json!({
        "name": "nuno",
        "version": env!("CARGO_PKG_VERSION"),
        "extensions": ["binary_tensor_data"],
    }))
}

/// KServe v2 model readiness (a loaded model is ready).
#[utoipa::path(get, path = "/v2/models/{id}/ready", tag = "kserve-v2",
    params(("id" = String, Path, description = "Model id")),
    responses((status = 200, description = "Ready", body = Object), (status = 404, description = "Unknown model", body = crate::server::V2ErrorBody)))]
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
    responses((status = 200, description = "Success", body = V2ModelMetadata), (status = 404, description = "Unknown model", body = crate::server::V2ErrorBody)))]
pub async fn v2_model_metadata(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Json<V2ModelMetadata>, V2Error> {
    let model = state.model(&id)?;
    Ok(Json(model_metadata(&model)))
}

/// What `infer` takes and answers for `model` (v2's model metadata, both transports).
pub(in crate::server) fn model_metadata(model: &LoadedModel) -> V2ModelMetadata {
    let (d, a) = (model.obs_dim() as i64, model.act_dim() as i64);
    V2ModelMetadata {
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
    }
}

/// One v2 tensor: its data inline (`data`, flattened row-major), or with the
/// binary tensor extension `parameters.binary_data_size` bytes after the JSON
/// header.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct InferTensor {
    pub name: String,
    #[serde(deserialize_with = "integers")]
    #[schema(value_type = Vec<u64>)]
    pub shape: Vec<usize>,
    pub datatype: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(value_type = Option<Vec<f64>>)]
    pub data: Option<serde_json::Value>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(value_type = Option<Object>)]
    pub parameters: Option<serde_json::Map<String, serde_json::Value>>,
}

/// One input tensor of a request: as [`InferTensor`], with its inline `data`
/// read straight into f32 while the body is parsed.
#[derive(Debug, Clone, Deserialize, ToSchema)]
pub struct InferInput {
    pub name: String,
    #[serde(deserialize_with = "integers")]
    #[schema(value_type = Vec<u64>)]
    pub shape: Vec<usize>,
    pub datatype: String,
    /// The values, flattened row-major (or `parameters.binary_data_size`
    /// bytes after the JSON header instead).
    #[serde(default)]
    #[schema(value_type = Option<Vec<f32>>)]
    pub data: Option<InputData>,
    #[serde(default)]
    #[schema(value_type = Option<Object>)]
    pub parameters: Option<serde_json::Map<String, serde_json::Value>>,
}

/// An input's inline values: a flat JSON array of numbers, 4 bytes each as
/// read (no JSON value tree). Numbers beyond f32's range read as ±inf and are
/// refused by name with the other non-finite values.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct InputData(pub Vec<f32>);

impl<'de> Deserialize<'de> for InputData {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct Numbers;
        impl<'de> serde::de::Visitor<'de> for Numbers {
            type Value = InputData;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a flat array of numbers")
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(
                self,
                mut seq: A,
            ) -> Result<InputData, A::Error> {
                let mut values = Vec::with_capacity(seq.size_hint().unwrap_or(0));
                while let Some(v) = seq.next_element::<f64>()? {
                    values.push(v as f32);
                }
                Ok(InputData(values))
            }
        }
        deserializer.deserialize_seq(Numbers)
    }
}

/// An output the client asks for; `parameters.binary_data: true` answers it
/// in binary.
#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct RequestedOutput {
    pub name: String,
    #[serde(default)]
    #[schema(value_type = Option<Object>)]
    pub parameters: Option<serde_json::Map<String, serde_json::Value>>,
}

#[derive(Debug, Clone, Deserialize, ToSchema)]
pub struct InferRequest {
    #[serde(default)]
    pub id: Option<String>,
    pub inputs: Vec<InferInput>,
    /// The outputs to answer (default: all of them).
    #[serde(default)]
    pub outputs: Option<Vec<RequestedOutput>>,
    /// `seed`, `penalty`, `noise_scale` (one particle per row);
    /// `binary_data_output: true` answers every output in binary.
    #[serde(default)]
    #[schema(value_type = Object)]
    pub parameters: serde_json::Map<String, serde_json::Value>,
}

#[derive(Debug, Clone, Serialize, Deserialize, ToSchema)]
pub struct InferResponse {
    pub model_name: String,
    pub model_version: String,
    pub id: Option<String>,
    /// `clipped_rows`: rows whose action was clipped into the model's action box.
    #[schema(value_type = Object)]
    pub parameters: serde_json::Map<String, serde_json::Value>,
    pub outputs: Vec<InferTensor>,
}

/// One EM step per row, in the v2 inference format. JSON, or the binary tensor
/// extension (`application/octet-stream` with `Inference-Header-Content-Length`)
/// both ways: inputs with `parameters.binary_data_size`, outputs in binary when
/// asked (`parameters.binary_data_output`, or `binary_data` per output).
#[utoipa::path(post, path = "/v2/models/{id}/infer", tag = "kserve-v2",
    params(("id" = String, Path, description = "Model id")),
    request_body(content(
        (InferRequest = "application/json"),
        (TensorBytes = "application/octet-stream"),
    )),
    responses(
        (status = 200, description = "Success", content((InferResponse = "application/json"), (TensorBytes = "application/octet-stream"))),
        (status = 400, description = "Malformed body", body = crate::server::V2ErrorBody),
        (status = 404, description = "Unknown model", body = crate::server::V2ErrorBody),
        (status = 422, description = "Wrong inputs, shapes or parameters, or over a limit. Inputs \
            `states` `[batch, obs_dim]` and `actions` `[batch, act_dim]` (the model's widths, in \
            `GET /v2/models/{id}`), FP32, `data` holding shape's product of numbers: rules a schema \
            cannot state", body = crate::server::V2ErrorBody),
    ))]
pub async fn infer(
    State(state): State<AppState>,
    Path(id): Path<String>,
    // The extractor's rejections answer in v2's error shape too.
    body: Result<RawBody, ApiError>,
) -> Result<Response, V2Error> {
    let body = body?;
    let header_length = header_length(&body)?;
    let mut r: InferRequest = body.json_prefix(header_length).await?;
    let model = state.model(&id)?;
    let mut tensors = std::mem::take(&mut r.inputs);
    let mut inputs = split_binary_tail(&mut tensors, &body.bytes[header_length..])?;
    let checked = check_infer(&state, &model, &r, &mut inputs)?;
    state.metrics.batch("infer", &id, checked.batch);
    let request_id = r.id.clone();
    // The answer is built in the compute work too: it is batch-sized.
    let response = state
        .compute(move |_| {
            let s = checked.run(&model);
            infer_response(&id, request_id, &s, &checked.wanted, checked.clipped_rows)
        })
        .await?;
    Ok(response)
}

/// An infer request checked against its model, over either transport (REST's
/// JSON or binary body, gRPC's messages): its rows, how to step them, what to
/// answer.
pub(in crate::server) struct CheckedInfer {
    pub batch: usize,
    states: Vec<f32>,
    actions: Vec<f32>,
    seed: u64,
    config: ParticleConfig,
    /// (name, binary?) of each output to answer, in order.
    pub wanted: Vec<(String, bool)>,
    /// Rows whose action was clipped into the model's action box.
    pub clipped_rows: usize,
}

impl CheckedInfer {
    /// One EM step per row, one particle each.
    pub fn run(&self, model: &LoadedModel) -> ParticleStep {
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        let (dynamics, rules) = (model.batch_dynamics(), &model.rules);
        step_particles(
            dynamics,
            rules,
            &self.states,
            &self.actions,
            self.config,
            &mut rng,
        )
    }
}

/// `r`'s inputs (each with its raw bytes, if sent so), parameters and outputs,
/// checked against `model` and the server's limits.
pub(in crate::server) fn check_infer(
    state: &AppState,
    model: &LoadedModel,
    r: &InferRequest,
    inputs: &mut [InputWithBytes],
) -> Result<CheckedInfer, ApiError> {
    let (obs_dim, act_dim) = (model.obs_dim(), model.act_dim());
    let max_batch = state.config.limits.max_batch;
    let states = input_values(inputs, "states", obs_dim, max_batch)?;
    let mut actions = input_values(inputs, "actions", act_dim, max_batch)?;
    let batch = states.len() / obs_dim;
    if actions.len() / act_dim != batch {
        return Err(ApiError::Invalid(
            "`states` and `actions` differ in rows".into(),
        ));
    }
    // `clip: false` asks for a 422 where an action leaves the box.
    let clip = flag_parameter(Some(&r.parameters), "clip")?.unwrap_or(true);
    let clipped_rows = clip_actions("actions", &mut actions, &model.action_space, clip)?;
    let number = |key: &str, default: f64| number_parameter(&r.parameters, key, default);
    let default_noise = f64::from(model.batch_dynamics().sample_noise_scale());
    Ok(CheckedInfer {
        batch,
        states,
        actions,
        seed: number("seed", 0.0)? as u64,
        config: ParticleConfig {
            particles: 1,
            penalty: number("penalty", 1.0)?,
            noise_scale: number("noise_scale", default_noise)? as f32,
        },
        wanted: wanted_outputs(r)?,
        clipped_rows,
    })
}

/// Where the JSON header ends: the whole body for JSON, the binary extension's
/// header length for a binary body (which must give it).
fn header_length(body: &RawBody) -> Result<usize, ApiError> {
    match (body.format, body.inference_header_length) {
        (_, Some(length)) => Ok(length),
        (Format::Json, None) => Ok(body.bytes.len()),
        (Format::Binary, None) => Err(ApiError::Invalid(format!(
            "a binary infer body needs the `{INFERENCE_HEADER_LENGTH}` header (the Open \
             Inference Protocol's binary tensor extension); JSON bodies need none"
        ))),
    }
}

/// An input and its raw bytes (none: its values are inline).
pub(in crate::server) type InputWithBytes<'a> = (&'a mut InferInput, Option<&'a [u8]>);

/// Each input with its slice of the binary tail (in order, by its
/// `binary_data_size`); the tail must be used up exactly.
fn split_binary_tail<'a>(
    inputs: &'a mut [InferInput],
    mut tail: &'a [u8],
) -> Result<Vec<InputWithBytes<'a>>, ApiError> {
    let mut split = Vec::with_capacity(inputs.len());
    for t in inputs.iter_mut() {
        let values = match binary_size(&t.name, t.parameters.as_ref())? {
            Some(size) if size > tail.len() => {
                return Err(ApiError::Malformed(format!(
                    "input `{}` has binary_data_size {size}, but only {} bytes are left",
                    t.name,
                    tail.len()
                )));
            }
            Some(size) => {
                let (data, rest) = tail.split_at(size);
                tail = rest;
                Some(data)
            }
            None => None,
        };
        split.push((t, values));
    }
    if !tail.is_empty() {
        return Err(ApiError::Malformed(format!(
            "{} bytes follow the last binary input",
            tail.len()
        )));
    }
    Ok(split)
}

/// Input `name`'s values, checked FP32, `[rows, width]` and within the batch limit.
fn input_values(
    inputs: &mut [InputWithBytes],
    name: &str,
    width: usize,
    max_batch: usize,
) -> Result<Vec<f32>, ApiError> {
    let (t, binary) = inputs
        .iter_mut()
        .find(|(t, _)| t.name == name)
        .ok_or_else(|| ApiError::Invalid(format!("input `{name}` is missing")))?;
    if t.datatype != "FP32" {
        return Err(ApiError::Invalid(format!(
            "input `{name}` must be FP32, got {}",
            t.datatype
        )));
    }
    // The declared rows first: no data is converted for a batch over the limit.
    within(
        "batch (shape[0])",
        t.shape.first().copied().unwrap_or(0),
        max_batch,
    )?;
    let values: Vec<f32> = match (*binary, t.data.take()) {
        (Some(bytes), _) => decode_fp32(name, bytes)?,
        (None, Some(InputData(values))) => values,
        (None, None) => {
            return Err(ApiError::Invalid(format!(
                "input `{name}` has no values: give `data` or parameters.binary_data_size (gRPC: fp32_contents or raw_input_contents)"
            )));
        }
    };
    let rows = flat(name, &values, width)?;
    if t.shape != [rows, width] {
        return Err(ApiError::Invalid(format!(
            "input `{name}` has shape {:?} but {} values; expected [{rows}, {width}]",
            t.shape,
            values.len()
        )));
    }
    Ok(values)
}

/// Parameter `key` as a number ≥ 0, `default` when absent.
fn number_parameter(
    parameters: &serde_json::Map<String, serde_json::Value>,
    key: &str,
    default: f64,
) -> Result<f64, ApiError> {
    match parameters.get(key) {
        None => Ok(default),
        Some(v) => v
            .as_f64()
            .filter(|x| x.is_finite() && *x >= 0.0)
            .ok_or_else(|| ApiError::Invalid(format!("parameter `{key}` must be a number ≥ 0"))),
    }
}

/// Parameter `key` as true or false, none when absent.
fn flag_parameter(
    parameters: Option<&serde_json::Map<String, serde_json::Value>>,
    key: &str,
) -> Result<Option<bool>, ApiError> {
    match parameters.and_then(|p| p.get(key)) {
        None => Ok(None),
        Some(v) => v
            .as_bool()
            .map(Some)
            .ok_or_else(|| ApiError::Invalid(format!("parameter `{key}` must be true or false"))),
    }
}

/// (name, binary?) of every output to answer, in the order asked (all of them
/// by default).
fn wanted_outputs(r: &InferRequest) -> Result<Vec<(String, bool)>, ApiError> {
    let binary_default =
        flag_parameter(Some(&r.parameters), "binary_data_output")?.unwrap_or(false);
    let Some(outputs) = &r.outputs else {
        return Ok(OUTPUTS
            .iter()
            .map(|name| (name.to_string(), binary_default))
            .collect());
    };
    outputs
        .iter()
        .map(|o| {
            if !OUTPUTS.contains(&o.name.as_str()) {
                return Err(ApiError::Invalid(format!(
                    "output `{}` does not exist; this model answers {OUTPUTS:?}",
                    o.name
                )));
            }
            let binary = flag_parameter(o.parameters.as_ref(), "binary_data")?;
            Ok((o.name.clone(), binary.unwrap_or(binary_default)))
        })
        .collect()
}

/// What `infer` answers, in the order of [`V2ModelMetadata::outputs`].
pub(in crate::server) const OUTPUTS: [&str; 8] = [
    "next_states",
    "mean",
    "sigma",
    "h_eta",
    "eta",
    "rewards",
    "penalized_rewards",
    "terminals",
];

/// Output `name` of a step (one of [`OUTPUTS`]): its shape and values.
pub(in crate::server) fn output<'a>(
    s: &'a ParticleStep,
    name: &str,
) -> (Vec<usize>, OutputData<'a>) {
    let (b, d) = (s.batch, s.obs_dim);
    match name {
        "next_states" => (vec![b, d], OutputData::Fp32(&s.next_states)),
        "mean" => (vec![b, d], OutputData::Fp32(&s.mean)),
        "sigma" => (vec![b, d], OutputData::Fp32(&s.sigma)),
        "h_eta" => (vec![b, d], OutputData::Fp32(&s.h_eta)),
        "eta" => (vec![b], OutputData::Fp32(&s.eta)),
        "rewards" => (vec![b], OutputData::Fp32(&s.rewards)),
        "penalized_rewards" => (vec![b], OutputData::Fp32(&s.penalized_rewards)),
        _ => (vec![b], OutputData::Bool(&s.terminals)),
    }
}

/// The answer with `wanted` outputs, each inline or in binary.
fn infer_response(
    id: &str,
    request_id: Option<String>,
    s: &ParticleStep,
    wanted: &[(String, bool)],
    clipped_rows: usize,
) -> Result<Response, ApiError> {
    let mut tails = Vec::new();
    let outputs = wanted
        .iter()
        .map(|(name, binary)| {
            let (shape, data) = output(s, name);
            let mut tensor = InferTensor {
                name: name.clone(),
                shape,
                datatype: data.datatype().into(),
                data: None,
                parameters: None,
            };
            if *binary {
                let bytes = data.to_bytes();
                tensor.parameters = Some(serde_json::Map::from_iter([(
                    "binary_data_size".to_string(),
                    serde_json::json!(bytes.len()),
                )]));
                tails.push(bytes);
            } else {
                tensor.data = Some(data.to_json());
            }
            tensor
        })
        .collect();
    let response = InferResponse {
        model_name: id.to_string(),
        model_version: "1".into(),
        id: request_id,
        parameters: serde_json::Map::from_iter([(
            "clipped_rows".to_string(),
            serde_json::json!(clipped_rows),
        )]),
        outputs,
    };
    if tails.is_empty() {
        return json_response(&response);
    }
    let header = serde_json::to_vec(&response).map_err(|e| ApiError::Internal(e.to_string()))?;
    Ok(binary_response(&header, &tails))
}
