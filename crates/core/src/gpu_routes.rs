//! Formulations for GPU inference, and the switch that turns each one off.
//!
//! Design decision: on burn's wgpu backend a pass of the update loop was bound by how many
//! kernels it launched (session 12: the synchronised stages summed to twice the unsynchronised
//! pass, and the CPU spent more time issuing work than the GPU computing it; session 17: ten or
//! more kernels per 3x3 convolution). Where burn's stock composition of an operation launches
//! many small kernels, or a slow one, GPU inference (a device other than the CPU, without
//! autodiff) takes a formulation from burn's operations with fewer: convolutions as one matrix
//! product over a column matrix gathered in one `select`, strided ones included, and with few
//! outputs the product before the shift, the bias and activation after it in the product's
//! epilogue, the ConvGRU's inputs gathered into columns once for both its products
//! (`matmul_conv`); the bilinear resize as burn's own `interpolate` kernel (`resample`); the
//! pyramid lookup as two gathers over all levels (`dgstereo_costvolume`). Each keeps the stock
//! path as its reference and is tested against it on the CPU, one by one and as a whole network
//! ([`set_routes_on_cpu`]); each can be turned off with `DGSTEREO_GPU_STOCK` (comma-separated
//! route names, or `all`; read once per process) so that a GPU run can measure what it gains.

use std::sync::OnceLock;
use std::sync::atomic::{AtomicBool, Ordering};

use burn::tensor::Device;

/// A GPU inference formulation that `DGSTEREO_GPU_STOCK` can turn off.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GpuRoute {
    /// Stride-1 convolutions as one matrix product (`conv`); off: burn's convolution.
    MatmulConv,
    /// The column matrix of that product gathered by one `select` (`im2col`); off: the shifted
    /// windows sliced one by one and concatenated.
    GatheredColumns,
    /// Strided convolutions through that product too, with gathered columns (`strided`); off:
    /// burn's convolution.
    StridedProducts,
    /// Convolutions with few outputs as the product first and the shifted sum after
    /// (`few-outputs`); off: the gathered columns.
    FewOutputs,
    /// Bilinear resizes as burn's `interpolate` (`resize`); off: the two interpolation-matrix
    /// products (the training path).
    Interpolate,
    /// The pyramid lookup as two gathers over all levels (`lookup`); off: a gather per level.
    GatheredLookup,
    /// The bias, activation and other element-wise work after a convolution's product issued on
    /// the product's own shape, with unpadded 1x1 convolutions taking the product too, so that
    /// burn's fusion runs it in the product's kernel (`epilogue`); off: after the reshape to
    /// NCHW, in kernels of their own, and burn's 1x1 convolution.
    FusedEpilogue,
    /// The ConvGRU's inputs gathered into columns once a step for its gates and its candidate
    /// (`shared-columns`); off: `[h, x]` and `[r·h, x]` each gathered whole.
    SharedColumns,
}

impl GpuRoute {
    /// The name `DGSTEREO_GPU_STOCK` knows the route by.
    pub fn name(self) -> &'static str {
        match self {
            Self::MatmulConv => "conv",
            Self::GatheredColumns => "im2col",
            Self::StridedProducts => "strided",
            Self::FewOutputs => "few-outputs",
            Self::Interpolate => "resize",
            Self::GatheredLookup => "lookup",
            Self::FusedEpilogue => "epilogue",
            Self::SharedColumns => "shared-columns",
        }
    }

    /// Whether `DGSTEREO_GPU_STOCK` leaves this route on.
    pub(crate) fn enabled(self) -> bool {
        static OFF: OnceLock<Vec<String>> = OnceLock::new();
        let off = OFF.get_or_init(|| {
            // The previous switch of the convolution route, still honoured.
            let legacy = std::env::var("DGSTEREO_GPU_CONV").is_ok_and(|v| v.eq_ignore_ascii_case("burn"));
            let mut names = parse_names(&std::env::var("DGSTEREO_GPU_STOCK").unwrap_or_default());
            if legacy {
                names.push(Self::MatmulConv.name().to_string());
            }
            names
        });
        !switched_off(off, self)
    }

    /// Whether the route applies to work on `device`: GPU inference, and not switched off.
    pub fn applies(self, device: &Device) -> bool {
        gpu_inference(device) && self.enabled()
    }
}

/// Inference on a device other than the CPU: no autodiff (training keeps the stock operations,
/// whose backward passes keep less), not burn's Flex backend (whose place the host kernels take)
/// unless [`set_routes_on_cpu`] asked for the routes there.
pub fn gpu_inference(device: &Device) -> bool {
    !device.is_autodiff() && (*device != Device::flex() || ROUTES_ON_CPU.load(Ordering::Relaxed))
}

static ROUTES_ON_CPU: AtomicBool = AtomicBool::new(false);

/// Lets CPU inference take the GPU routes too (off by default), for the whole process: with the
/// host kernels off as well ([`crate::device::set_host_kernels`]), the CPU then computes what GPU
/// inference computes, so the GPU's composition can be checked and debugged on a machine without
/// a GPU (`dgstereo bench --kernels gpu-routes`). Where a host kernel is on and applies, it still
/// runs first.
pub fn set_routes_on_cpu(enabled: bool) {
    ROUTES_ON_CPU.store(enabled, Ordering::Relaxed);
}

/// The lower-cased, trimmed names of a comma-separated list.
fn parse_names(list: &str) -> Vec<String> {
    list.split(',').map(|s| s.trim().to_ascii_lowercase()).filter(|s| !s.is_empty()).collect()
}

/// Whether `names` turns `route` off (by its name or `all`).
fn switched_off(names: &[String], route: GpuRoute) -> bool {
    names.iter().any(|n| n == "all" || n == route.name())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn routes_are_switched_off_by_name_or_all() {
        let names = parse_names(" Resize, lookup ,,");
        assert_eq!(names, ["resize", "lookup"]);
        assert!(switched_off(&names, GpuRoute::Interpolate) && switched_off(&names, GpuRoute::GatheredLookup));
        assert!(!switched_off(&names, GpuRoute::MatmulConv) && !switched_off(&names, GpuRoute::GatheredColumns));
        let all = parse_names("all");
        for route in [
            GpuRoute::MatmulConv,
            GpuRoute::GatheredColumns,
            GpuRoute::StridedProducts,
            GpuRoute::FewOutputs,
            GpuRoute::Interpolate,
            GpuRoute::GatheredLookup,
            GpuRoute::FusedEpilogue,
            GpuRoute::SharedColumns,
        ] {
            assert!(switched_off(&all, route), "{route:?}");
        }
    }

    /// The CPU never takes a GPU route, with or without autodiff.
    #[test]
    fn the_cpu_takes_no_route() {
        let cpu = Device::flex();
        assert!(!gpu_inference(&cpu) && !gpu_inference(&cpu.clone().autodiff()));
        assert!(!GpuRoute::MatmulConv.applies(&cpu) && !GpuRoute::GatheredLookup.applies(&cpu));
    }
}
