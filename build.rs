//! Build script shared by `nuno` and `nuno-trainer`: bakes the directory of the
//! fetched libmujoco into the rpath so binaries and tests run without
//! LD_LIBRARY_PATH, and fails early with the make target to run when the MuJoCo
//! runtime has not been fetched; for `nuno` itself, generates the ONNX
//! messages (`export/`) from the vendored `proto/onnx/onnx.proto` and, with the
//! server, the Open Inference Protocol's gRPC service from `proto/oip/`.

use std::path::Path;

fn main() {
    println!("cargo::rerun-if-env-changed=MUJOCO_DYNAMIC_LINK_DIR");
    println!("cargo::rerun-if-env-changed=NUNO_MJCF_DIR");
    let lib_dir = std::env::var("MUJOCO_DYNAMIC_LINK_DIR").unwrap_or_default();
    let mjcf_dir = std::env::var("NUNO_MJCF_DIR").unwrap_or_default();
    let lib = Path::new(&lib_dir).join("libmujoco.so");
    // Every task's MJCF model, embedded by `src/envs/task.rs`.
    let models = [
        "hopper.xml",
        "half_cheetah.xml",
        "walker2d.xml",
        "swimmer.xml",
        "inverted_pendulum.xml",
        "ant.xml",
    ];
    let missing = std::iter::once(lib.clone())
        .chain(models.iter().map(|m| Path::new(&mjcf_dir).join(m)))
        .find(|path| !path.is_file());
    if let Some(path) = missing {
        panic!(
            "the MuJoCo runtime is missing ({}): run `make mujoco`, which fetches \
             libmujoco from the `mujoco` wheel and the MJCF models from the `gymnasium` wheel",
            path.display()
        );
    }
    println!("cargo::rerun-if-changed={}", lib.display());
    println!("cargo::rustc-link-arg=-Wl,-rpath,{lib_dir}");
    if std::env::var("CARGO_PKG_NAME").as_deref() == Ok("nuno") {
        generate_onnx_messages();
        if std::env::var_os("CARGO_FEATURE_SERVER").is_some() {
            generate_inference_service();
        }
    }
}

/// `inference.rs` in OUT_DIR: the messages and tonic's server trait of
/// `inference.GRPCInferenceService`, from KServe's compiled
/// `grpc_predict_v2.proto` (`proto/oip/extract.py` says where it comes from).
fn generate_inference_service() {
    use prost::Message;
    let manifest = std::env::var("CARGO_MANIFEST_DIR").unwrap_or_default();
    let file = Path::new(&manifest).join("proto/oip/grpc_predict_v2.binpb");
    println!("cargo::rerun-if-changed={}", file.display());
    let bytes = std::fs::read(&file).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
    let descriptors = prost_types::FileDescriptorSet::decode(bytes.as_slice())
        .unwrap_or_else(|e| panic!("{} is not a FileDescriptorSet: {e}", file.display()));
    tonic_prost_build::configure()
        .build_client(false)
        .compile_fds(descriptors)
        .unwrap_or_else(|e| panic!("generating the inference service failed: {e}"));
}

/// `onnx.rs` in OUT_DIR: prost's types for ONNX's `ModelProto` and the rest,
/// compiled by protox (no protoc needed).
fn generate_onnx_messages() {
    let manifest = std::env::var("CARGO_MANIFEST_DIR").unwrap_or_default();
    let proto = Path::new(&manifest).join("proto/onnx");
    println!("cargo::rerun-if-changed={}", proto.display());
    let descriptors = protox::compile([proto.join("onnx.proto")], [&proto])
        .unwrap_or_else(|e| panic!("proto/onnx/onnx.proto does not compile: {e}"));
    prost_build::Config::new()
        .compile_fds(descriptors)
        .unwrap_or_else(|e| panic!("generating the ONNX messages failed: {e}"));
}
