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
            Self::Gpu => {
                let device = Device::vulkan(Default::default());
                probe_gpu(&device)?;
                Ok(device)
            }
            #[cfg(not(feature = "gpu"))]
            Self::Gpu => Err(crate::Error::Config(
                "this binary was built without the GPU backend; rebuild with `--features gpu`".into(),
            )),
        }
    }
}

/// Runs one tiny operation on the GPU so that a machine without a usable Vulkan adapter gives an
/// error here instead of a panic inside the backend later (burn's wgpu runtime panics when it
/// finds no adapter). The panic hook is silenced during the probe.
#[cfg(feature = "gpu")]
fn probe_gpu(device: &Device) -> crate::Result<()> {
    let previous = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let d = device.clone();
    let result = std::panic::catch_unwind(move || burn::tensor::Tensor::<1>::zeros([1], &d).into_data());
    std::panic::set_hook(previous);
    result.map(|_| ()).map_err(|_| {
        crate::Error::Other(
            "no usable GPU: burn's wgpu backend found no Vulkan adapter (install a Vulkan driver and loader, \
             or use --device cpu)"
                .into(),
        )
    })
}

/// The default device: the Flex CPU backend.
pub fn default_device() -> Device {
    Device::flex()
}

static HOST_KERNELS: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(true);

/// Turns the hand-written host kernels on or off for the whole process (on by default); off,
/// burn's operations run everywhere, which is how `dgstereo bench --kernels stock` measures what
/// the kernels gain.
pub fn set_host_kernels(enabled: bool) {
    HOST_KERNELS.store(enabled, std::sync::atomic::Ordering::Relaxed);
}

/// Whether the hand-written host kernels apply on `device`: the plain CPU backend (Flex) without
/// autodiff, i.e. inference on the CPU, unless [`set_host_kernels`] turned them off. Everywhere
/// else burn's operations run.
pub fn host_kernels_apply(device: &Device) -> bool {
    HOST_KERNELS.load(std::sync::atomic::Ordering::Relaxed) && *device == Device::flex() && !device.is_autodiff()
}
