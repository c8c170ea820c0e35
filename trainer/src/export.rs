//! `nuno-trainer export`: a model folder as files another runtime runs
//! without nuno (`nuno::export`): the SDE step and the policy beside it as
//! ONNX graphs, and the contract naming their inputs and outputs.

use std::path::PathBuf;

use anyhow::Context;
use nuno::export::{CONTRACT_FILE, export_onnx};

/// What the model is written as.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum Format {
    /// ONNX graphs (opset 17) for ONNX Runtime and other ONNX runtimes.
    Onnx,
}

#[derive(Debug, clap::Args)]
pub struct Args {
    /// Model directory (a neural SDE's model.json + dynamics.safetensors; its policy.safetensors is exported too).
    #[arg(long)]
    model: PathBuf,
    #[arg(long, value_enum)]
    format: Format,
    /// Where to write the files (default: `<model>/onnx`).
    #[arg(long)]
    out: Option<PathBuf>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let Format::Onnx = args.format;
    let out = args.out.unwrap_or_else(|| args.model.join("onnx"));
    let contract = export_onnx(&args.model, &out)
        .with_context(|| format!("exporting {}", args.model.display()))?;
    let files = std::iter::once(&contract.model).chain(&contract.policy);
    for graph in files {
        let inputs: Vec<&str> = graph.inputs.iter().map(|t| t.name.as_str()).collect();
        let outputs: Vec<&str> = graph.outputs.iter().map(|t| t.name.as_str()).collect();
        println!(
            "wrote {}: ({}) → ({})",
            out.join(&graph.file).display(),
            inputs.join(", "),
            outputs.join(", ")
        );
    }
    println!(
        "wrote {} (opset {})",
        out.join(CONTRACT_FILE).display(),
        contract.opset
    );
    Ok(())
}
