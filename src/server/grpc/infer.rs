//! `ModelInfer`'s messages to and from the REST infer's checked form
//! ([`check_infer`]): the same inputs, parameters, limits and errors, with
//! tensors as `fp32_contents` or `raw_input_contents` and every output
//! answered in `raw_output_contents` (as Triton answers).

use std::collections::HashMap;

use super::proto::infer_parameter::ParameterChoice;
use super::proto::model_infer_request::{InferInputTensor, InferRequestedOutputTensor};
use super::proto::model_infer_response::InferOutputTensor;
use super::proto::{InferParameter, ModelInferRequest, ModelInferResponse};
use crate::agent::ParticleStep;
use crate::server::routes::kserve::{
    CheckedInfer, InferInput, InferRequest, InputData, InputWithBytes, RequestedOutput,
    check_infer, output,
};
use crate::server::{ApiError, AppState, LoadedModel};

/// The protocol's parameters as the REST body's JSON map. A parameter whose
/// value this protocol version cannot carry (a newer client's double) is named.
fn parameters(
    given: &HashMap<String, InferParameter>,
) -> Result<serde_json::Map<String, serde_json::Value>, ApiError> {
    given
        .iter()
        .map(|(key, parameter)| {
            let value = match &parameter.parameter_choice {
                Some(ParameterChoice::BoolParam(b)) => serde_json::json!(b),
                Some(ParameterChoice::Int64Param(i)) => serde_json::json!(i),
                // A number too precise for int64 travels as a string ("0.5").
                Some(ParameterChoice::StringParam(s)) => s
                    .parse::<f64>()
                    .map_or_else(|_| serde_json::json!(s), |x| serde_json::json!(x)),
                None => {
                    return Err(ApiError::Invalid(format!(
                        "parameter `{key}` carries no bool, int64 or string value (give a fraction as a string, \"0.5\")"
                    )));
                }
            };
            Ok((key.clone(), value))
        })
        .collect()
}

/// A dimension of `tensor`'s shape as a size.
fn dimensions(tensor: &str, shape: &[i64]) -> Result<Vec<usize>, ApiError> {
    shape
        .iter()
        .map(|&d| {
            usize::try_from(d).map_err(|_| {
                ApiError::Invalid(format!(
                    "input `{tensor}` has a negative dimension in {shape:?}"
                ))
            })
        })
        .collect()
}

/// An input as the REST body's, its `fp32_contents` as inline data (an input
/// with other contents then has no data, which the checks name).
fn input(tensor: &mut InferInputTensor) -> Result<InferInput, ApiError> {
    // Moved out, not copied: a batch's values are the request's bulk.
    let fp32 = (tensor.contents.as_mut()).map(|c| std::mem::take(&mut c.fp32_contents));
    Ok(InferInput {
        name: tensor.name.clone(),
        shape: dimensions(&tensor.name, &tensor.shape)?,
        datatype: tensor.datatype.clone(),
        data: fp32.filter(|v| !v.is_empty()).map(InputData),
        parameters: None,
    })
}

fn requested(output: &InferRequestedOutputTensor) -> Result<RequestedOutput, ApiError> {
    Ok(RequestedOutput {
        name: output.name.clone(),
        parameters: Some(parameters(&output.parameters)?),
    })
}

/// `request` checked as the REST infer checks its body: inputs `states` and
/// `actions` as FP32 `[batch, width]`, in `fp32_contents` or, for every input
/// at once, `raw_input_contents`.
pub fn check(
    state: &AppState,
    model: &LoadedModel,
    request: &mut ModelInferRequest,
) -> Result<CheckedInfer, ApiError> {
    let raw = &request.raw_input_contents;
    if !raw.is_empty() && raw.len() != request.inputs.len() {
        return Err(ApiError::Invalid(format!(
            "raw_input_contents has {} entries for {} inputs: give one per input, or none",
            raw.len(),
            request.inputs.len()
        )));
    }
    let body = InferRequest {
        id: Some(request.id.clone()),
        inputs: Vec::new(),
        outputs: (!request.outputs.is_empty())
            .then(|| {
                request
                    .outputs
                    .iter()
                    .map(requested)
                    .collect::<Result<_, _>>()
            })
            .transpose()?,
        parameters: parameters(&request.parameters)?,
    };
    let mut inputs = request
        .inputs
        .iter_mut()
        .map(input)
        .collect::<Result<Vec<_>, _>>()?;
    let mut with_bytes: Vec<InputWithBytes> = inputs
        .iter_mut()
        .enumerate()
        .map(|(i, t)| (t, raw.get(i).map(Vec::as_slice)))
        .collect();
    check_infer(state, model, &body, &mut with_bytes)
}

/// The step's `wanted` outputs, little-endian in `raw_output_contents`.
pub fn response(
    model: &str,
    id: String,
    step: &ParticleStep,
    checked: &CheckedInfer,
) -> ModelInferResponse {
    let (outputs, raw) = checked
        .wanted
        .iter()
        .map(|(name, _)| {
            let (shape, data) = output(step, name);
            let tensor = InferOutputTensor {
                name: name.clone(),
                datatype: data.datatype().to_string(),
                shape: shape.iter().map(|&d| d as i64).collect(),
                ..Default::default()
            };
            (tensor, data.to_bytes())
        })
        .unzip();
    let clipped = InferParameter {
        parameter_choice: Some(ParameterChoice::Int64Param(checked.clipped_rows as i64)),
    };
    ModelInferResponse {
        model_name: model.to_string(),
        model_version: "1".to_string(),
        id,
        parameters: HashMap::from([("clipped_rows".to_string(), clipped)]),
        outputs,
        raw_output_contents: raw,
    }
}
