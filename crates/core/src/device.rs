//! Which device tensors live on.
//!
//! burn 0.22 carries the backend in the [`Device`] rather than in a type parameter, so every
//! module of the workspace is backend-agnostic: the same code runs on the Flex CPU backend (the
//! default), on the GPU through wgpu/Vulkan (feature `gpu`), and trains when the device has
//! autodiff enabled ([`Device::autodiff`]).

use burn::tensor::Device;
use serde::{Deserialize, Serialize};

/// A device named by the user (`cpu` or `gpu`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DeviceChoice {
    /// burn's Flex backend: pure Rust, multi-threaded with rayon.
    #[default]
    Cpu,
    /// burn's wgpu backend on Vulkan; needs the `gpu` feature.
    Gpu,
}

impl std::str::FromStr for DeviceChoice {
    type Err = crate::Error;
    fn from_str(s: &str) -> crate::Result<Self> {
        match s.to_ascii_lowercase().as_str() {
            "cpu" | "flex" => Ok(Self::Cpu),
            "gpu" | "wgpu" | "vulkan" => Ok(Self::Gpu),
            other => Err(crate::Error::Config(format!("unknown device '{other}' (expected 'cpu' or 'gpu')"))),
        }
    }
}

impl DeviceChoice {
    /// The burn device, or an error when the GPU was asked for in a build without it.
    pub fn device(self) -> crate::Result<Device> {
        match self {
            Self::Cpu => Ok(Device::flex()),
            #[cfg(feature = "gpu")]
            Self::Gpu => Ok(Device::vulkan(Default::default())),
            #[cfg(not(feature = "gpu"))]
            Self::Gpu => Err(crate::Error::Config(
                "this binary was built without the GPU backend; rebuild with `--features gpu`".into(),
            )),
        }
    }
}

/// The default device: the Flex CPU backend.
pub fn default_device() -> Device {
    Device::flex()
}
