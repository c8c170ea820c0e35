//! Versioned JSON metadata files and the weights they vouch for: written
//! atomically, read back with the schema version and the weights' hash checked.

use std::path::Path;

use serde::Serialize;
use serde::de::DeserializeOwned;

use super::safetensors_file::{parse_safetensors, write_bytes};
use super::tensors::NamedTensors;
use super::{ArtifactError, sha256_hex};

/// Writes `value` as pretty JSON to `path`, atomically.
pub fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<(), ArtifactError> {
    let json = serde_json::to_vec_pretty(value).map_err(|e| ArtifactError::Json {
        file: path.to_path_buf(),
        message: e.to_string(),
    })?;
    write_bytes(path, &json)
}

/// Reads JSON from `path`, refusing any `schema_version` other than `expected`.
pub fn read_versioned_json<T: DeserializeOwned>(
    path: &Path,
    expected: u32,
) -> Result<T, ArtifactError> {
    read_versioned_json_filled(path, expected, |_| {})
}

/// As [`read_versioned_json`], with `fill` adding fields that files of the same
/// schema written before the fields existed lack (their old meaning, stated).
pub fn read_versioned_json_filled<T: DeserializeOwned>(
    path: &Path,
    expected: u32,
    fill: impl FnOnce(&mut serde_json::Value),
) -> Result<T, ArtifactError> {
    let bytes = std::fs::read(path).map_err(|e| ArtifactError::io(path, e))?;
    let json_error = |e: serde_json::Error| ArtifactError::Json {
        file: path.to_path_buf(),
        message: e.to_string(),
    };
    let mut value: serde_json::Value = serde_json::from_slice(&bytes).map_err(json_error)?;
    let version = value.get("schema_version").and_then(|v| v.as_u64());
    if version != Some(u64::from(expected)) {
        return Err(ArtifactError::Schema {
            file: path.to_path_buf(),
            found: version.map_or("none".into(), |v| v.to_string()),
            expected,
        });
    }
    fill(&mut value);
    serde_json::from_value(value).map_err(json_error)
}

/// Reads a safetensors file whose SHA-256 must be `sha256`.
pub fn read_checked_weights(path: &Path, sha256: &str) -> Result<NamedTensors, ArtifactError> {
    let bytes = std::fs::read(path).map_err(|e| ArtifactError::io(path, e))?;
    if sha256_hex(&bytes) != sha256 {
        return Err(ArtifactError::HashMismatch {
            file: path.to_path_buf(),
        });
    }
    parse_safetensors(&bytes, path)
}
