//! A model folder as ONNX files that run without nuno (ONNX Runtime on a
//! robot, say): the neural SDE's Euler–Maruyama step with the task's reward
//! and termination (`model.onnx`), the policy saved beside it (`policy.onnx`),
//! and `contract.json`, which names every input and output, its shape and what
//! it means. Graphs are written with prost's messages of ONNX's own
//! `onnx.proto` (`proto/onnx/`), at [`OPSET`].

mod actor;
mod graph;
mod proto;
mod sde_step;
mod task_rules;

use std::path::{Path, PathBuf};

use burn::tensor::Device;
use prost::Message;
use serde::{Deserialize, Serialize};

pub use graph::{BATCH, IR_VERSION, OPSET};

use crate::artifact::{ArtifactError, ModelFolder, load_model_policy};
use crate::envs::Rules;
use crate::shared::write_atomically;
use actor::actor_graph;
use proto::onnx::{ModelProto, ValueInfoProto, tensor_proto::DataType, type_proto};
use sde_step::sde_step_graph;

/// Everything that can stop an export.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    #[error(transparent)]
    Artifact(#[from] ArtifactError),
    #[error("{0}")]
    NotExportable(String),
    #[error("{file}: {source}")]
    Io {
        file: PathBuf,
        #[source]
        source: std::io::Error,
    },
}

/// The file the SDE step is written to.
pub const MODEL_FILE: &str = "model.onnx";
/// The file the policy is written to.
pub const POLICY_FILE: &str = "policy.onnx";
/// The file naming both graphs' inputs and outputs.
pub const CONTRACT_FILE: &str = "contract.json";

/// One input or output: its name, element type and shape (`"batch"` first).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TensorContract {
    pub name: String,
    pub dtype: String,
    pub shape: Vec<serde_json::Value>,
}

/// One exported graph.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GraphContract {
    pub file: String,
    pub inputs: Vec<TensorContract>,
    pub outputs: Vec<TensorContract>,
    /// What the graph computes and how to feed it.
    pub notes: Vec<String>,
}

/// `contract.json`: what was exported, from which weights, at which opset.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ExportContract {
    pub opset: i64,
    pub ir_version: i64,
    pub source: String,
    pub weights_sha256: String,
    pub model: GraphContract,
    pub policy: Option<GraphContract>,
}

const MODEL_NOTES: [&str; 5] = [
    "One Euler–Maruyama step of the neural SDE (eq. 5, 8): next_state = mean + (sigma + h_eta)·noise·sqrt(dt); Σ = sigma + h_eta.",
    "noise is ε ~ N(0, I) times the noise scale (the server's noise_scale; 0 gives the mean). Its width is the integrated state's: the observation, plus the cumulative reward r_c for a model that learns its reward.",
    "action is clipped to the task's action box first, as the server's step does by default (clip: true).",
    "reward is the task's r(s, a, s') on next_state (a model that learns its reward: the sampled r_c); the penalised reward is reward − λ·eta.",
    "terminal is the task's termination rule on next_state (bool).",
];

const POLICY_NOTES: [&str; 3] = [
    "SAC's tanh-Gaussian actor: deterministic_action = centre + half·tanh(μ(s)), what evaluation and the server's act (deterministic) use.",
    "sampled_action = centre + half·tanh(μ(s) + σ(s)·noise) for noise ε ~ N(0, I), the server's act (sampled); log_prob is log π(sampled_action | observation).",
    "The action box's centre and half-width are folded in.",
];

fn dtype(elem_type: Option<i32>) -> String {
    match elem_type.and_then(|t| DataType::try_from(t).ok()) {
        Some(DataType::Float) => "float32",
        Some(DataType::Bool) => "bool",
        _ => "unknown",
    }
    .to_string()
}

fn tensor_contract(info: &ValueInfoProto) -> TensorContract {
    let tensor = match info.r#type.as_ref().and_then(|t| t.value.as_ref()) {
        Some(type_proto::Value::TensorType(tensor)) => Some(tensor),
        _ => None,
    };
    let dims = tensor.and_then(|t| t.shape.as_ref()).map(|s| &s.dim[..]);
    let shape = dims.unwrap_or_default().iter().map(|d| match &d.value {
        Some(proto::onnx::tensor_shape_proto::dimension::Value::DimValue(n)) => (*n).into(),
        Some(proto::onnx::tensor_shape_proto::dimension::Value::DimParam(p)) => p.clone().into(),
        None => serde_json::Value::Null,
    });
    TensorContract {
        name: info.name.clone().unwrap_or_default(),
        dtype: dtype(tensor.and_then(|t| t.elem_type)),
        shape: shape.collect(),
    }
}

/// The contract of `model` written to `file`: its graph's inputs and outputs.
fn graph_contract(model: &ModelProto, file: &str, notes: &[&str]) -> GraphContract {
    let graph = model.graph.as_ref();
    let infos = |pick: fn(&proto::onnx::GraphProto) -> &Vec<ValueInfoProto>| {
        graph
            .map(pick)
            .into_iter()
            .flatten()
            .map(tensor_contract)
            .collect()
    };
    GraphContract {
        file: file.to_string(),
        inputs: infos(|g| &g.input),
        outputs: infos(|g| &g.output),
        notes: notes.iter().map(|n| n.to_string()).collect(),
    }
}

fn write_file(path: &Path, bytes: &[u8]) -> Result<(), ExportError> {
    let io = |source| ExportError::Io {
        file: path.to_path_buf(),
        source,
    };
    write_atomically(path, |tmp| std::fs::write(tmp, bytes).map_err(io), io)
}

/// Writes `model.onnx` (and `policy.onnx`, where the folder holds a policy)
/// and `contract.json` for the model folder `dir` into `out`. Refused, before
/// anything is written: a model that is not a neural SDE, and a system whose
/// reward and termination are not a built-in task's.
pub fn export_onnx(dir: &Path, out: &Path) -> Result<ExportContract, ExportError> {
    let device = Device::flex();
    let folder = ModelFolder::load(dir, &device)?;
    let ModelFolder::NeuralSde { model, metadata } = &folder else {
        return Err(ExportError::NotExportable(format!(
            "{}: a Gaussian ensemble (MOPO's model) cannot be exported; ONNX export covers the neural SDE",
            dir.display()
        )));
    };
    let system = folder.system()?.ok_or_else(|| {
        ExportError::NotExportable(format!(
            "{}: model.json names no task or system, so the step's reward and termination are unknown",
            dir.display()
        ))
    })?;
    let Rules::Task(rules) = folder.rules(&system)? else {
        return Err(ExportError::NotExportable(format!(
            "{}: the model is of a system file ({}); its reward and termination are not exported yet, only a built-in task's",
            dir.display(),
            system.name()
        )));
    };
    let shape = (system.shape()).map_err(|e| ExportError::NotExportable(e.to_string()))?;
    let step = sde_step_graph(model, &rules.terms(), &shape.action_space());
    let (obs_dim, act_dim) = (model.constants.spec.obs_dim, model.constants.spec.act_dim);
    let policy = load_model_policy(dir, obs_dim, act_dim, &device)?;
    let policy = policy.map(|(actor, _)| actor_graph(&actor));

    let contract = ExportContract {
        opset: OPSET,
        ir_version: IR_VERSION,
        source: dir.display().to_string(),
        weights_sha256: metadata.weights_sha256.clone(),
        model: graph_contract(&step, MODEL_FILE, &MODEL_NOTES),
        policy: policy
            .as_ref()
            .map(|p| graph_contract(p, POLICY_FILE, &POLICY_NOTES)),
    };
    write_file(&out.join(MODEL_FILE), &step.encode_to_vec())?;
    if let Some(policy) = &policy {
        write_file(&out.join(POLICY_FILE), &policy.encode_to_vec())?;
    }
    let json = serde_json::to_vec_pretty(&contract).map_err(|e| ExportError::Io {
        file: out.join(CONTRACT_FILE),
        source: e.into(),
    })?;
    write_file(&out.join(CONTRACT_FILE), &json)?;
    Ok(contract)
}
