//! Request and response bodies: JSON, or safetensors bytes
//! (`application/octet-stream`) for large batches, so 50 000 × 17 floats do not
//! pay for text. Every rejection becomes an [`ApiError`].

use std::collections::HashMap;

use axum::body::Bytes;
use axum::extract::{FromRequest, Request};
use axum::http::{HeaderMap, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::Serialize;
use serde::de::DeserializeOwned;

use super::ApiError;
use super::AppState;
use crate::artifact::{NamedTensors, parse_safetensors_with_metadata, safetensors_bytes};

/// The MIME type of binary tensor bodies.
pub const BINARY: &str = "application/octet-stream";

/// A safetensors file as a request or response body (f32 tensors, options as
/// string metadata in its header).
#[derive(utoipa::ToSchema)]
#[schema(value_type = String, format = Binary)]
pub struct TensorBytes(pub Vec<u8>);

/// How a request body is encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    Json,
    Binary,
}

/// The raw request body, with body-size and read errors mapped to [`ApiError`].
pub struct RawBody {
    pub format: Format,
    pub bytes: Bytes,
    /// `Inference-Header-Content-Length`: the Open Inference Protocol's binary
    /// tensor extension, a JSON header of this many bytes and raw tensors after it.
    pub inference_header_length: Option<usize>,
}

/// The header of the Open Inference Protocol's binary tensor extension.
pub const INFERENCE_HEADER_LENGTH: &str = "inference-header-content-length";

impl FromRequest<AppState> for RawBody {
    type Rejection = ApiError;

    async fn from_request(req: Request, state: &AppState) -> Result<Self, Self::Rejection> {
        let format = request_format(req.headers())?;
        let inference_header_length = match req.headers().get(INFERENCE_HEADER_LENGTH) {
            None => None,
            Some(value) => Some(
                value
                    .to_str()
                    .ok()
                    .and_then(|v| v.trim().parse::<usize>().ok())
                    .ok_or_else(|| {
                        ApiError::Malformed(format!(
                            "header `{INFERENCE_HEADER_LENGTH}` must be a byte count, got {value:?}"
                        ))
                    })?,
            ),
        };
        let limit = state.config.limits.max_body_bytes;
        let bytes = Bytes::from_request(req, state).await.map_err(|e| {
            if e.status() == StatusCode::PAYLOAD_TOO_LARGE {
                ApiError::TooLarge(limit)
            } else {
                ApiError::Malformed(e.body_text())
            }
        })?;
        Ok(Self {
            format,
            bytes,
            inference_header_length,
        })
    }
}

/// JSON bodies from this size up are parsed on a blocking thread: a batch of
/// thousands of rows takes milliseconds to parse, which would stall every
/// other request waiting on the async runtime's few threads.
const OFF_RUNTIME_BYTES: usize = 64 * 1024;

impl RawBody {
    /// The body as JSON of type `T` (binary bodies are refused for JSON-only routes).
    pub async fn json<T: DeserializeOwned + Send + 'static>(&self) -> Result<T, ApiError> {
        if self.format == Format::Binary {
            return Err(ApiError::UnsupportedMediaType {
                given: BINARY.into(),
                accepted: "application/json",
            });
        }
        json_off_runtime(self.bytes.clone()).await
    }

    /// The first `length` bytes as JSON of type `T`, whatever the content type
    /// (the JSON header of a binary-extension body).
    pub async fn json_prefix<T: DeserializeOwned + Send + 'static>(
        &self,
        length: usize,
    ) -> Result<T, ApiError> {
        if length > self.bytes.len() {
            return Err(ApiError::Malformed(format!(
                "`{INFERENCE_HEADER_LENGTH}` is {length} but the body has {} bytes",
                self.bytes.len()
            )));
        }
        json_off_runtime(self.bytes.slice(..length)).await
    }

    /// The body as safetensors: named f32 tensors and the header's string metadata.
    pub fn tensors(&self) -> Result<(NamedTensors, HashMap<String, String>), ApiError> {
        parse_safetensors_with_metadata(&self.bytes, std::path::Path::new("request body"))
            .map_err(|e| ApiError::Malformed(e.to_string()))
    }
}

/// Parses `bytes` as JSON, on a blocking thread from [`OFF_RUNTIME_BYTES`] up.
async fn json_off_runtime<T: DeserializeOwned + Send + 'static>(
    bytes: Bytes,
) -> Result<T, ApiError> {
    if bytes.len() < OFF_RUNTIME_BYTES {
        return parse_json(&bytes);
    }
    tokio::task::spawn_blocking(move || parse_json(&bytes))
        .await
        .map_err(|e| ApiError::Internal(format!("parsing the body failed: {e}")))?
}

fn parse_json<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, ApiError> {
    serde_json::from_slice(bytes).map_err(|e| ApiError::Malformed(e.to_string()))
}

/// A JSON response body, serialised where this is called: routes with
/// batch-sized answers call it inside their compute work, off the async runtime.
pub fn json_response<T: Serialize>(value: &T) -> Result<Response, ApiError> {
    let bytes = serde_json::to_vec(value).map_err(|e| ApiError::Internal(e.to_string()))?;
    Ok(([(header::CONTENT_TYPE, "application/json")], bytes).into_response())
}

fn request_format(headers: &HeaderMap) -> Result<Format, ApiError> {
    let Some(value) = headers.get(header::CONTENT_TYPE) else {
        // curl -d without -H sends no JSON type; JSON is the default.
        return Ok(Format::Json);
    };
    let value = value.to_str().unwrap_or_default();
    let mime = value
        .split(';')
        .next()
        .unwrap_or_default()
        .trim()
        .to_ascii_lowercase();
    match mime.as_str() {
        "application/json" | "application/x-www-form-urlencoded" | "" => Ok(Format::Json),
        BINARY => Ok(Format::Binary),
        _ => Err(ApiError::UnsupportedMediaType {
            given: value.to_string(),
            accepted: "application/json or application/octet-stream",
        }),
    }
}

/// The answer's format a client asks for with `Accept`: binary when it lists
/// `application/octet-stream` (and not JSON first), JSON otherwise.
pub fn answer_format(headers: &HeaderMap) -> Format {
    let accept = headers
        .get(header::ACCEPT)
        .and_then(|v| v.to_str().ok())
        .unwrap_or_default();
    let position = |mime: &str| accept.find(mime);
    match (position(BINARY), position("application/json")) {
        (Some(binary), Some(json)) if json < binary => Format::Json,
        (Some(_), _) => Format::Binary,
        _ => Format::Json,
    }
}

/// A safetensors response body.
/// `tensors` as a safetensors answer whose header metadata says the `noise_scale`
/// the samples were drawn at.
pub fn tensors_response(
    tensors: &NamedTensors,
    noise_scale: f32,
    clipped_rows: usize,
) -> Result<Response, ApiError> {
    let metadata = HashMap::from([
        ("noise_scale".to_string(), noise_scale.to_string()),
        ("clipped_rows".to_string(), clipped_rows.to_string()),
    ]);
    let bytes = safetensors_bytes(tensors, Some(metadata))
        .map_err(|e| ApiError::Internal(e.to_string()))?;
    Ok(([(header::CONTENT_TYPE, BINARY)], bytes).into_response())
}

/// A binary request's metadata option, or its default.
pub fn metadata_option<T: std::str::FromStr>(
    metadata: &HashMap<String, String>,
    key: &str,
    default: T,
) -> Result<T, ApiError> {
    match metadata.get(key) {
        None => Ok(default),
        Some(text) => text.parse().map_err(|_| {
            ApiError::Invalid(format!("metadata `{key}` = `{text}` is not a valid value"))
        }),
    }
}

/// A binary request's metadata holds only the options its route takes (as
/// JSON bodies refuse unknown fields).
pub fn refuse_unknown_metadata(
    metadata: &HashMap<String, String>,
    known: &[&str],
) -> Result<(), ApiError> {
    let mut unknown: Vec<&String> = metadata
        .keys()
        .filter(|k| !known.contains(&k.as_str()))
        .collect();
    unknown.sort();
    match unknown.first() {
        None => Ok(()),
        Some(key) => Err(ApiError::Invalid(format!(
            "metadata `{key}` is not an option of this route (its options: {})",
            known.join(", ")
        ))),
    }
}
