//! Reading and writing named f32 tensors as a `.safetensors` file, with every
//! malformed case reported by name.

use std::collections::HashMap;
use std::path::Path;

use safetensors::tensor::{Dtype, SafeTensors, TensorView};

use super::ArtifactError;
use super::tensors::NamedTensors;
use crate::shared::write_atomically;

/// Serialises `tensors` (f32, little-endian) with `metadata` in the header.
pub fn safetensors_bytes(
    tensors: &NamedTensors,
    metadata: Option<HashMap<String, String>>,
) -> Result<Vec<u8>, ArtifactError> {
    let bytes: Vec<_> = tensors
        .iter()
        .map(|(name, (shape, values))| (name, shape, le_bytes(values)))
        .collect();
    let views = bytes
        .iter()
        .map(|(name, shape, raw)| {
            TensorView::new(Dtype::F32, (*shape).clone(), raw)
                .map(|view| ((*name).clone(), view))
                .map_err(|e| ArtifactError::Safetensors(format!("tensor `{name}`: {e}")))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let bytes = safetensors::serialize(views, metadata)
        .map_err(|e| ArtifactError::Safetensors(e.to_string()))?;
    Ok(with_sorted_header(bytes))
}

/// `bytes` with its JSON header's keys sorted: the crate writes the metadata
/// in a `HashMap`'s order, which differs from run to run, and the same
/// tensors should be the same bytes. Same keys, same length: the 8-byte
/// length prefix and the data offsets stay as they are.
fn with_sorted_header(mut bytes: Vec<u8>) -> Vec<u8> {
    let Some(length) = (bytes.get(..8))
        .and_then(|prefix| <[u8; 8]>::try_from(prefix).ok())
        .and_then(|prefix| usize::try_from(u64::from_le_bytes(prefix)).ok())
    else {
        return bytes;
    };
    let Some(header) = bytes.get(8..8 + length) else {
        return bytes;
    };
    // serde_json's map is a BTreeMap: re-serialising sorts the keys.
    let sorted = serde_json::from_slice::<serde_json::Value>(header)
        .and_then(|value| serde_json::to_vec(&value));
    if let Ok(sorted) = sorted
        && sorted.len() <= length
    {
        bytes[8..8 + sorted.len()].copy_from_slice(&sorted);
        bytes[8 + sorted.len()..8 + length].fill(b' ');
    }
    bytes
}

/// `values` as little-endian bytes: borrowed where f32 already is (no copy of
/// an answer that may be hundreds of MB), converted elsewhere.
fn le_bytes(values: &[f32]) -> std::borrow::Cow<'_, [u8]> {
    if cfg!(target_endian = "little") {
        // SAFETY: an f32 is 4 initialised bytes with no padding, u8 has
        // alignment 1, and the byte slice covers exactly the f32 slice's memory.
        std::borrow::Cow::Borrowed(unsafe {
            std::slice::from_raw_parts(values.as_ptr().cast::<u8>(), std::mem::size_of_val(values))
        })
    } else {
        std::borrow::Cow::Owned(values.iter().flat_map(|v| v.to_le_bytes()).collect())
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_same_tensors_and_metadata_are_the_same_bytes() {
        let tensors = NamedTensors::from([
            ("b".to_string(), (vec![2], vec![1.0, 2.0])),
            ("a".to_string(), (vec![1, 3], vec![3.0, 4.0, 5.0])),
        ]);
        let keys: Vec<String> = (0..16).map(|i| format!("key{i}")).collect();
        let metadata = |order: &mut dyn Iterator<Item = &String>| -> HashMap<String, String> {
            order.map(|k| (k.clone(), format!("{k}-value"))).collect()
        };
        let first = safetensors_bytes(&tensors, Some(metadata(&mut keys.iter()))).unwrap();
        let second = safetensors_bytes(&tensors, Some(metadata(&mut keys.iter().rev()))).unwrap();
        assert_eq!(first, second);
        let (read, read_metadata) =
            parse_safetensors_with_metadata(&first, Path::new("bytes")).unwrap();
        assert_eq!(read, tensors);
        assert_eq!(read_metadata, metadata(&mut keys.iter()));
    }
}
