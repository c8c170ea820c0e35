//! `step`'s safetensors bodies, as the server reads and writes them: tensors
//! `states` and `actions`, the options as string metadata; the answer's
//! tensors read back into the server's own [`ParticleStep`].

use std::collections::HashMap;
use std::path::Path;

use nuno::artifact::{NamedTensors, parse_safetensors_with_metadata, safetensors_bytes};

use crate::{ClientError, ParticleStep, StepRequest, StepResponse};

/// The request as a safetensors body.
pub fn step_body(request: &StepRequest) -> Result<Vec<u8>, ClientError> {
    let tensor =
        |rows: &nuno::server::Rows| (vec![rows.len(), rows.width()], rows.values().to_vec());
    let tensors = NamedTensors::from([
        ("states".to_string(), tensor(&request.states)),
        ("actions".to_string(), tensor(&request.actions)),
    ]);
    let mut metadata = HashMap::from([
        ("particles".to_string(), request.particles.to_string()),
        ("seed".to_string(), request.seed.to_string()),
        ("penalty".to_string(), request.penalty.to_string()),
        ("clip".to_string(), request.clip.to_string()),
    ]);
    if let Some(scale) = request.noise_scale {
        metadata.insert("noise_scale".to_string(), scale.to_string());
    }
    safetensors_bytes(&tensors, Some(metadata)).map_err(|e| ClientError::Decode(e.to_string()))
}

/// Model `id`'s safetensors answer as the JSON answer's [`StepResponse`].
pub fn step_answer(id: &str, bytes: &[u8]) -> Result<StepResponse, ClientError> {
    let bad = |what: String| ClientError::Decode(format!("binary step answer: {what}"));
    let (mut tensors, metadata) = parse_safetensors_with_metadata(bytes, Path::new("step answer"))
        .map_err(|e| bad(e.to_string()))?;
    let mut take = |name: &str| {
        tensors
            .remove(name)
            .ok_or_else(|| bad(format!("no `{name}` tensor")))
    };
    let (shape, next_states) = take("next_states")?;
    let [batch, particles, obs_dim] = shape[..] else {
        return Err(bad(format!(
            "`next_states` has shape {shape:?}, not [batch, particles, obs_dim]"
        )));
    };
    let step = ParticleStep {
        batch,
        particles,
        obs_dim,
        mean: take("mean")?.1,
        sigma: take("sigma")?.1,
        h_eta: take("h_eta")?.1,
        eta: take("eta")?.1,
        next_states,
        rewards: take("rewards")?.1,
        penalized_rewards: take("penalized_rewards")?.1,
        terminals: take("terminals")?.1.iter().map(|&t| t != 0.0).collect(),
    };
    let number = |key: &str| -> Result<f64, ClientError> {
        let text = metadata
            .get(key)
            .ok_or_else(|| bad(format!("no `{key}` metadata")))?;
        text.parse()
            .map_err(|_| bad(format!("metadata `{key}` = `{text}`")))
    };
    Ok(StepResponse::from_particles(
        id,
        &step,
        number("noise_scale")? as f32,
        number("clipped_rows")? as usize,
    ))
}
