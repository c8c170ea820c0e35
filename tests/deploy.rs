//! The deployment manifests in `deploy/`, validated offline: Kubernetes objects
//! against the Kubernetes schemas, KServe objects' pod parts likewise, their
//! cross-references, and the server flags they pass (`tests/python/k8s_validate.py`).

mod common;

use std::path::Path;

#[test]
#[cfg_attr(
    not(feature = "external-tests"),
    ignore = "needs the Python venv and its Kubernetes schemas (`make venv`); `make test` runs it"
)]
fn deploy_manifests_validate_against_the_kubernetes_schemas() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let work = tempfile::tempdir().unwrap();
    common::run_python(
        "k8s_validate.py",
        &[
            root.join("deploy").to_str().unwrap(),
            env!("CARGO_BIN_EXE_nuno-server"),
        ],
        work.path(),
    );
}
