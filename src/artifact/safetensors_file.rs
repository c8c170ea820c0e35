//! Reading and writing named f32 tensors as a `.safetensors` file, with every
//! malformed case reported by name.

use std::collections::HashMap;
use std::path::Path;

use safetensors::tensor::{Dtype, SafeTensors, TensorView};

use super::tensors::NamedTensors;
use super::{ArtifactError, write_atomically};

/// Serialises `tensors` (f32, little-endian) with `metadata` in the header.
pub fn safetensors_bytes(
    tensors: &NamedTensors,
    metadata: Option<HashMap<String, String>>,
) -> Result<Vec<u8>, ArtifactError> {
    let bytes: Vec<(String, Vec<usize>, Vec<u8>)> = tensors
        .iter()
        .map(|(name, (shape, values))| {
            let raw = values.iter().flat_map(|v| v.to_le_bytes()).collect();
            (name.clone(), shape.clone(), raw)
        })
        .collect();
    let views = bytes
        .iter()
        .map(|(name, shape, raw)| {
            TensorView::new(Dtype::F32, shape.clone(), raw)
                .map(|view| (name.clone(), view))
                .map_err(|e| ArtifactError::Safetensors(format!("tensor `{name}`: {e}")))
        })
        .collect::<Result<Vec<_>, _>>()?;
    safetensors::serialize(views, metadata).map_err(|e| ArtifactError::Safetensors(e.to_string()))
}

/// Writes `bytes` to `path` atomically.
pub fn write_bytes(path: &Path, bytes: &[u8]) -> Result<(), ArtifactError> {
    write_atomically(
        path,
        |tmp| std::fs::write(tmp, bytes).map_err(|e| ArtifactError::io(tmp, e)),
        |e| ArtifactError::io(path, e),
    )
}

/// Parses a safetensors buffer into named f32 tensors; any other dtype is refused.
pub fn parse_safetensors(bytes: &[u8], file: &Path) -> Result<NamedTensors, ArtifactError> {
    parse_safetensors_with_metadata(bytes, file).map(|(tensors, _)| tensors)
}

/// [`parse_safetensors`], and the header's string metadata, from one parse of
/// the header.
pub fn parse_safetensors_with_metadata(
    bytes: &[u8],
    file: &Path,
) -> Result<(NamedTensors, HashMap<String, String>), ArtifactError> {
    let (header, parsed) =
        SafeTensors::read_metadata(bytes).map_err(|e| ArtifactError::Corrupt {
            file: file.to_path_buf(),
            message: e.to_string(),
        })?;
    // read_metadata checks that the offsets tile the data; `get` keeps a
    // malformed file an error even if it did not.
    let data = bytes.get(8 + header..).unwrap_or_default();
    let mut tensors = NamedTensors::new();
    for (name, info) in parsed.tensors() {
        if info.dtype != Dtype::F32 {
            return Err(ArtifactError::TensorDtype {
                name,
                got: format!("{:?}", info.dtype),
            });
        }
        let (start, end) = info.data_offsets;
        let raw = data.get(start..end).ok_or_else(|| ArtifactError::Corrupt {
            file: file.to_path_buf(),
            message: format!("tensor `{name}` lies outside the file"),
        })?;
        let values = raw
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        tensors.insert(name, (info.shape.clone(), values));
    }
    Ok((tensors, parsed.metadata().clone().unwrap_or_default()))
}
