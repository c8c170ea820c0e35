//! Build script shared by `nuno` and `nuno-trainer`: bakes the directory of the
//! fetched libmujoco into the rpath so binaries and tests run without
//! LD_LIBRARY_PATH, and fails early with the make target to run when the MuJoCo
//! runtime has not been fetched.

use std::path::Path;

fn main() {
    println!("cargo::rerun-if-env-changed=MUJOCO_DYNAMIC_LINK_DIR");
    println!("cargo::rerun-if-env-changed=NUNO_MJCF_DIR");
    let lib_dir = std::env::var("MUJOCO_DYNAMIC_LINK_DIR").unwrap_or_default();
    let mjcf_dir = std::env::var("NUNO_MJCF_DIR").unwrap_or_default();
    let lib = Path::new(&lib_dir).join("libmujoco.so");
    let hopper = Path::new(&mjcf_dir).join("hopper.xml");
    if !lib.is_file() || !hopper.is_file() {
        panic!(
            "the MuJoCo runtime is missing ({} or {}): run `make mujoco`, which fetches \
             libmujoco from the `mujoco` wheel and the MJCF models from the `gymnasium` wheel",
            lib.display(),
            hopper.display()
        );
    }
    println!("cargo::rerun-if-changed={}", lib.display());
    println!("cargo::rustc-link-arg=-Wl,-rpath,{lib_dir}");
}
