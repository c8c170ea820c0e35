//! Reading and writing named f32 tensors as a `.safetensors` file, with every
//! malformed case reported by name.

use std::path::Path;

use safetensors::tensor::{Dtype, SafeTensors, TensorView};

use super::tensors::NamedTensors;
use super::{ArtifactError, write_atomically};

/// Serialises `tensors` (f32, little-endian) with `metadata` in the header.
pub fn safetensors_bytes(
    tensors: &NamedTensors,
    metadata: Option<std::collections::HashMap<String, String>>,
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
    let parsed = SafeTensors::deserialize(bytes).map_err(|e| ArtifactError::Corrupt {
        file: file.to_path_buf(),
        message: e.to_string(),
    })?;
    let mut tensors = NamedTensors::new();
    for (name, view) in parsed.tensors() {
        if view.dtype() != Dtype::F32 {
            return Err(ArtifactError::TensorDtype {
                name,
                got: format!("{:?}", view.dtype()),
            });
        }
        let values = view
            .data()
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        tensors.insert(name, (view.shape().to_vec(), values));
    }
    Ok(tensors)
}
