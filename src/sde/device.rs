//! Which burn device models train and run on: burn 0.22 picks the backend at
//! run time from the `Device`, so one model code path serves the CPU (`flex`,
//! the default) and GPUs (`wgpu`, behind the cargo feature of that name).

use std::fmt;
use std::str::FromStr;

use burn::tensor::Device;
use serde::{Deserialize, Serialize};

/// A compute device by name.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ComputeDevice {
    /// burn's flex backend: pure Rust, the fastest CPU backend for these small MLPs.
    #[default]
    Cpu,
    /// burn's wgpu backend on the default adapter (needs the `wgpu` cargo feature).
    Wgpu,
}

impl ComputeDevice {
    /// The burn device, or why it is not available in this build.
    pub fn device(self) -> Result<Device, String> {
        match self {
            ComputeDevice::Cpu => Ok(Device::flex()),
            #[cfg(feature = "wgpu")]
            ComputeDevice::Wgpu => Ok(Device::wgpu(burn::tensor::DeviceKind::DefaultDevice)),
            #[cfg(not(feature = "wgpu"))]
            ComputeDevice::Wgpu => {
                Err("this build has no wgpu backend: rebuild with `--features wgpu`".into())
            }
        }
    }
}

impl FromStr for ComputeDevice {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "cpu" | "flex" => Ok(Self::Cpu),
            "wgpu" | "gpu" => Ok(Self::Wgpu),
            other => Err(format!("unknown device `{other}` (expected cpu or wgpu)")),
        }
    }
}

impl fmt::Display for ComputeDevice {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            ComputeDevice::Cpu => "cpu",
            ComputeDevice::Wgpu => "wgpu",
        })
    }
}
