//! The Open Inference Protocol's binary tensor extension on HTTP, the one
//! Triton's and KServe's clients use for large tensors: a JSON header of
//! `Inference-Header-Content-Length` bytes, then the raw little-endian data of
//! every tensor whose `parameters.binary_data_size` is set, in order.

use axum::http::header;
use axum::response::{IntoResponse, Response};

use crate::server::ApiError;
use crate::server::body::{BINARY, INFERENCE_HEADER_LENGTH};

/// `parameters.binary_data_size` of a tensor: how many bytes of the body's
/// tail hold its data (`None`: the data is inline JSON).
pub fn binary_size(
    name: &str,
    parameters: Option<&serde_json::Map<String, serde_json::Value>>,
) -> Result<Option<usize>, ApiError> {
    let Some(size) = parameters.and_then(|p| p.get("binary_data_size")) else {
        return Ok(None);
    };
    size.as_u64().map(|n| Some(n as usize)).ok_or_else(|| {
        ApiError::Invalid(format!(
            "input `{name}`: parameters.binary_data_size must be a byte count, got {size}"
        ))
    })
}

/// Little-endian FP32 values from `bytes`.
pub fn decode_fp32(name: &str, bytes: &[u8]) -> Result<Vec<f32>, ApiError> {
    if !bytes.len().is_multiple_of(4) {
        return Err(ApiError::Invalid(format!(
            "input `{name}` has {} bytes of binary data, not a whole number of FP32 values",
            bytes.len()
        )));
    }
    Ok(bytes
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect())
}

/// An output's data as the extension sends it: FP32 little-endian, BOOL one byte.
pub enum OutputData<'a> {
    Fp32(&'a [f32]),
    Bool(&'a [bool]),
}

impl OutputData<'_> {
    pub fn datatype(&self) -> &'static str {
        match self {
            OutputData::Fp32(_) => "FP32",
            OutputData::Bool(_) => "BOOL",
        }
    }

    pub fn to_json(&self) -> serde_json::Value {
        match self {
            OutputData::Fp32(v) => serde_json::json!(v),
            OutputData::Bool(v) => serde_json::json!(v),
        }
    }

    pub fn to_bytes(&self) -> Vec<u8> {
        match self {
            OutputData::Fp32(v) => v.iter().flat_map(|x| x.to_le_bytes()).collect(),
            OutputData::Bool(v) => v.iter().map(|&b| u8::from(b)).collect(),
        }
    }
}

/// A body of `header` (the JSON response) followed by `tails`, with the
/// extension's length header.
pub fn binary_response(header: &[u8], tails: &[Vec<u8>]) -> Response {
    let mut body = Vec::with_capacity(header.len() + tails.iter().map(Vec::len).sum::<usize>());
    body.extend_from_slice(header);
    for tail in tails {
        body.extend_from_slice(tail);
    }
    (
        [
            (header::CONTENT_TYPE, BINARY.to_string()),
            (
                header::HeaderName::from_static(INFERENCE_HEADER_LENGTH),
                header.len().to_string(),
            ),
        ],
        body,
    )
        .into_response()
}
