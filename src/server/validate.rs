//! Checks on client-supplied batches: not empty, the right widths, finite
//! values, within the configured limits. Every message names the field.

use super::ApiError;
use super::body::Format;

/// Checks a flat row-major buffer: whole rows of `width`, all finite.
pub fn flat(field: &str, values: &[f32], width: usize) -> Result<usize, ApiError> {
    if values.is_empty() {
        return Err(ApiError::Invalid(format!(
            "`{field}` is empty: send at least one row"
        )));
    }
    if width == 0 || !values.len().is_multiple_of(width) {
        return Err(ApiError::Invalid(format!(
            "`{field}` has {} values, not a whole number of rows of width {width}",
            values.len()
        )));
    }
    finite(field, values, width)?;
    Ok(values.len() / width)
}

fn finite(field: &str, values: &[f32], width: usize) -> Result<(), ApiError> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(i) => Err(ApiError::Invalid(format!(
            "`{field}[{}][{}]` is not a finite number",
            i / width,
            i % width
        ))),
        None => Ok(()),
    }
}

/// Clips `actions` (`[rows, space.len()]`) into the model's action box, as
/// MuJoCo clips controls to their range; the number of rows changed. With
/// `clip` false an action outside its box is refused, naming the first.
pub fn clip_actions(
    field: &str,
    actions: &mut [f32],
    space: &[(f32, f32)],
    clip: bool,
) -> Result<usize, ApiError> {
    let mut clipped_rows = 0;
    for (row, values) in actions.chunks_exact_mut(space.len()).enumerate() {
        let mut clipped = false;
        for (j, (value, &(low, high))) in values.iter_mut().zip(space).enumerate() {
            if (low..=high).contains(value) {
                continue;
            }
            if !clip {
                return Err(ApiError::Invalid(format!(
                    "`{field}[{row}][{j}]` = {value} is outside the action box [{low}, {high}] \
                     (send `clip: true`, the default, to clip it)"
                )));
            }
            *value = value.clamp(low, high);
            clipped = true;
        }
        clipped_rows += usize::from(clipped);
    }
    Ok(clipped_rows)
}

/// `value` of `field` must lie in `1..=max`.
pub fn within(field: &str, value: usize, max: usize) -> Result<(), ApiError> {
    if value == 0 {
        return Err(ApiError::Invalid(format!("`{field}` must be at least 1")));
    }
    if value > max {
        return Err(ApiError::OverLimit(format!(
            "`{field}` is {value}, over this server's limit of {max}"
        )));
    }
    Ok(())
}

/// A finite, non-negative number.
pub fn non_negative(field: &str, value: f64) -> Result<(), ApiError> {
    if !value.is_finite() || value < 0.0 {
        return Err(ApiError::Invalid(format!(
            "`{field}` must be a finite number ≥ 0, got {value}"
        )));
    }
    Ok(())
}

/// Bytes one number of an answer takes: 4 as f32 in binary, at most 16 as JSON
/// text (the longest f32 `serde_json` writes, `-1.2345678e-12`, and a comma).
fn bytes_per_value(format: Format) -> usize {
    match format {
        Format::Binary => 4,
        Format::Json => 16,
    }
}

/// Checked before any work: an answer of `values` numbers (`what` says how
/// they were counted) must fit in `max_bytes` in `format`.
pub fn answer_within(
    what: &str,
    values: usize,
    format: Format,
    max_bytes: usize,
) -> Result<(), ApiError> {
    let bytes = values.saturating_mul(bytes_per_value(format));
    if bytes > max_bytes {
        let hint = match format {
            Format::Json => "; binary answers (application/octet-stream) take a quarter",
            Format::Binary => "",
        };
        return Err(ApiError::OverLimit(format!(
            "the answer would take up to {bytes} bytes ({values} values: {what}), over this \
             server's limit of {max_bytes} bytes (max_answer_bytes); send fewer rows, particles \
             or steps{hint}"
        )));
    }
    Ok(())
}
