//! Which device tensors live on.
//!
//! burn 0.22 carries the backend in the [`Device`] rather than in a type parameter, so every
//! module of the workspace is backend-agnostic: the same code runs on the Flex CPU backend (the
//! default), on the GPU through wgpu/Vulkan (feature `gpu`), and trains when the device has
//! autodiff enabled ([`Device::autodiff`]).
//!
//! The float precision is a setting of the device too ([`Precision`]): burn creates a float
//! tensor in the device's default float dtype unless told otherwise, so configuring the device
//! before the first tensor ([`DeviceChoice::device_with_precision`]) runs a whole forward pass in
//! half precision without touching the model code. burn keeps a loaded weight in the dtype of
//! its file, so weights read from an f32 checkpoint must be cast afterwards
//! ([`cast_float_params`]); the hand-written host kernels are f32 code and stand aside on any
//! other precision (the kernels crate's dispatch reads [`float_dtype`]).

use burn::module::{Module, ModuleMapper, Param};
use burn::tensor::{Device, FloatDType, Tensor};
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
            other => Err(crate::Error::config("device", format!("unknown device '{other}' (expected 'cpu' or 'gpu')"))),
        }
    }
}

impl DeviceChoice {
    /// The burn device, or an error when the GPU was asked for in a build without it.
    pub fn device(self) -> crate::Result<Device> {
        self.device_with_precision(Precision::F32)
    }

    /// The burn device with `precision` as its default float dtype, configured before anything
    /// else touches it (the GPU probe included); on the GPU, a machine without a usable Vulkan
    /// adapter is an error. Errors when the backend lacks the dtype, or when
    /// tensors already exist on the device in another precision: burn fixes a device's float
    /// dtype at its first tensor, once per process.
    pub fn device_with_precision(self, precision: Precision) -> crate::Result<Device> {
        match self {
            Self::Cpu => configured(Device::flex(), precision),
            #[cfg(any(feature = "gpu", feature = "gpu-wgsl"))]
            Self::Gpu => configured_gpu(gpu_device(), precision),
            #[cfg(not(any(feature = "gpu", feature = "gpu-wgsl")))]
            Self::Gpu => Err(crate::Error::config(
                "device",
                "this binary was built without the GPU backend; rebuild with `--features gpu`",
            )),
        }
    }

    /// The device of one of `local_size` processes sharing a machine (the ranks of a
    /// data-parallel run): the CPU as [`DeviceChoice::device`] (the processes divide the cores
    /// among themselves); the GPU, when several processes share the machine, its discrete
    /// adapter number `local_rank`, else the default adapter.
    pub fn device_for_local_rank(self, local_rank: usize, local_size: usize) -> crate::Result<Device> {
        match self {
            #[cfg(any(feature = "gpu", feature = "gpu-wgsl"))]
            Self::Gpu if local_size > 1 => {
                configured_gpu(gpu_device_of(burn::tensor::DeviceKind::DiscreteGpu(local_rank)), Precision::F32)
            }
            _ => {
                let _ = (local_rank, local_size);
                self.device()
            }
        }
    }
}

/// The float precision a whole forward pass runs in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Precision {
    /// IEEE single precision, the reference (and the only one the host kernels compute).
    #[default]
    F32,
    /// IEEE half precision (11-bit significand, range ±65504): what GPU tensor cores multiply.
    F16,
    /// bfloat16 (8-bit significand, f32's range).
    Bf16,
}

impl std::str::FromStr for Precision {
    type Err = crate::Error;
    fn from_str(s: &str) -> crate::Result<Self> {
        match s.to_ascii_lowercase().as_str() {
            "f32" | "float32" | "fp32" => Ok(Self::F32),
            "f16" | "float16" | "fp16" | "half" => Ok(Self::F16),
            "bf16" | "bfloat16" => Ok(Self::Bf16),
            other => Err(crate::Error::config(
                "precision",
                format!("unknown precision '{other}' (expected f32, f16 or bf16)"),
            )),
        }
    }
}

impl std::fmt::Display for Precision {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::F32 => "f32",
            Self::F16 => "f16",
            Self::Bf16 => "bf16",
        })
    }
}

impl Precision {
    /// burn's float dtype of this precision.
    pub fn float_dtype(self) -> FloatDType {
        match self {
            Self::F32 => FloatDType::F32,
            Self::F16 => FloatDType::F16,
            Self::Bf16 => FloatDType::BF16,
        }
    }
}

/// `device` with `precision` as its default float dtype. A device already in that precision
/// (burn's default is f32, and a process configures a device once) is returned as it is.
fn configured(mut device: Device, precision: Precision) -> crate::Result<Device> {
    let wanted = precision.float_dtype();
    if float_dtype(&device) == wanted {
        return Ok(device);
    }
    let result = device.configure(wanted);
    result.map_err(|e| {
        crate::Error::config(
            "precision",
            match e {
                burn::tensor::DeviceError::UnsupportedDType { device: name, .. } => {
                    format!("{precision}: the backend of device {name} does not compute in this dtype")
                }
                burn::tensor::DeviceError::AlreadyInitialized { device: name } => format!(
                    "{precision}: device {name} is already set to {:?} (burn fixes a device's float \
                 dtype at its first tensor or configuration, once per process)",
                    float_dtype(&device)
                ),
            },
        )
    })?;
    Ok(device)
}

/// The default float dtype of `device`: the dtype of every float tensor created on it without
/// an explicit one.
pub fn float_dtype(device: &Device) -> FloatDType {
    device.settings().float_dtype
}

/// Casts every float parameter of `module` to `dtype` (a no-op for those already in it).
///
/// burn's stores keep a loaded tensor in the dtype of its file, so on a device configured for
/// half precision a network loaded from an f32 checkpoint holds f32 weights next to f16
/// activations, which the backends do not mix; this brings the weights to the device's
/// precision ([`float_dtype`]).
pub fn cast_float_params<M: Module>(module: M, dtype: FloatDType) -> M {
    struct Caster(FloatDType);
    impl ModuleMapper for Caster {
        fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
            let dtype = self.0;
            param.map(|t| crate::tensor::cast_float(t, dtype))
        }
    }
    module.map(&mut Caster(dtype))
}

/// Sets `precision` on the GPU device and runs one tiny operation there, so that a machine
/// without a usable Vulkan adapter gives an error here instead of a panic inside the backend
/// later (burn's wgpu runtime panics when it finds no adapter, and asking whether the adapter
/// computes in a dtype starts that runtime). The panic hook is silenced meanwhile.
#[cfg(any(feature = "gpu", feature = "gpu-wgsl"))]
fn configured_gpu(device: Device, precision: Precision) -> crate::Result<Device> {
    let previous = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let result = std::panic::catch_unwind(move || {
        let device = configured(device, precision)?;
        let _ = burn::tensor::Tensor::<1>::zeros([1], &device).into_data();
        Ok(device)
    });
    std::panic::set_hook(previous);
    result.unwrap_or_else(|_| {
        Err(crate::Error::unsupported(
            "the GPU device",
            "no usable GPU: burn's wgpu backend found no Vulkan adapter (install a Vulkan driver and loader, \
             or use --device cpu)",
        ))
    })
}

/// The GPU: burn's wgpu backend pinned to Vulkan (SPIR-V kernels).
#[cfg(feature = "gpu")]
fn gpu_device() -> Device {
    gpu_device_of(Default::default())
}

/// The adapter `kind` on Vulkan.
#[cfg(feature = "gpu")]
fn gpu_device_of(kind: burn::tensor::DeviceKind) -> Device {
    Device::vulkan(kind)
}

/// The GPU of the `gpu-wgsl` build: burn's wgpu backend on whichever adapter it finds, with WGSL
/// kernels (a software Vulkan driver's compiler takes these where it crashes on the SPIR-V ones).
#[cfg(all(feature = "gpu-wgsl", not(feature = "gpu")))]
fn gpu_device() -> Device {
    gpu_device_of(Default::default())
}

/// The adapter `kind`, with WGSL kernels.
#[cfg(all(feature = "gpu-wgsl", not(feature = "gpu")))]
fn gpu_device_of(kind: burn::tensor::DeviceKind) -> Device {
    Device::wgpu(kind)
}

/// The default device: the Flex CPU backend.
pub fn default_device() -> Device {
    Device::flex()
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::nn::conv::Conv2dConfig;
    use burn::tensor::DType;

    #[test]
    fn precisions_parse_and_unknown_ones_are_named() {
        for p in [Precision::F32, Precision::F16, Precision::Bf16] {
            assert_eq!(p.to_string().parse::<Precision>().unwrap(), p);
        }
        assert_eq!("FP16".parse::<Precision>().unwrap(), Precision::F16);
        let e = "f8".parse::<Precision>().unwrap_err().to_string();
        assert!(e.contains("'f8'") && e.contains("bf16"), "{e}");
    }

    /// The default precision needs no configuration, so asking for it on the (already used)
    /// f32 CPU device is not an error.
    #[test]
    fn f32_is_the_cpu_default() {
        let device = DeviceChoice::Cpu.device().unwrap();
        let _ = Tensor::<1>::zeros([1], &device);
        let again = DeviceChoice::Cpu.device_with_precision(Precision::F32).unwrap();
        assert_eq!(float_dtype(&again), FloatDType::F32);
    }

    /// Every weight and bias of a module takes the asked dtype, values rounded to it.
    #[test]
    fn float_params_are_cast() {
        let device = default_device();
        let conv = Conv2dConfig::new([3, 4], [3, 3]).init(&device);
        let before = crate::tensor::to_vec(conv.weight.val());
        for (dtype, tolerance) in [(FloatDType::F16, 1e-3), (FloatDType::BF16, 8e-3)] {
            let cast = cast_float_params(conv.clone(), dtype);
            assert_eq!(cast.weight.val().dtype(), DType::from(dtype));
            assert_eq!(cast.bias.as_ref().unwrap().val().dtype(), DType::from(dtype));
            let after = crate::tensor::to_vec(cast.weight.val());
            let worst = before.iter().zip(&after).map(|(a, b)| ((a - b) / a.abs().max(1e-3)).abs()).fold(0.0, f32::max);
            assert!(worst < tolerance, "{dtype:?}: relative rounding {worst}");
            assert!(before != after, "{dtype:?}: no value was rounded");
        }
        let same = cast_float_params(conv, FloatDType::F32);
        assert_eq!(crate::tensor::to_vec(same.weight.val()), before);
    }
}
