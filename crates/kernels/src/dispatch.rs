//! The one place that decides where an operation is computed.
//!
//! Every operation of the face ([`crate::ops`]) asks [`path`] and runs the implementation it
//! names; no other code looks at the device to choose a kernel. The choice depends on the
//! device (the Flex CPU backend or another), its float dtype, whether it records gradients, and
//! the process's [`Settings`](crate::settings::Settings). Tests and comparisons can pin a path
//! for a closure on the calling thread ([`with_path`]), which is how one test body runs on every
//! path ([`crate::test_paths!`]).

use std::cell::Cell;

use burn::tensor::{Device, FloatDType};
use dgstereo_core::device::float_dtype;

use crate::settings::{GpuRoute, settings};

/// Where an operation is computed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Path {
    /// Hand-written host code (`crate::host`): inference on the Flex CPU backend in f32.
    Host,
    /// burn's operations arranged for fewer kernel launches (`crate::gpu`): GPU inference.
    Gpu,
    /// burn's own operations: the reference, the autodiff path, and everything else.
    Stock,
}

impl Path {
    /// The path's name, as benchmarks and test names print it.
    pub fn name(self) -> &'static str {
        match self {
            Self::Host => "host",
            Self::Gpu => "gpu-formulation",
            Self::Stock => "stock",
        }
    }
}

/// The operations the dispatch chooses a path for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Op {
    /// 2-D convolution, with or without an epilogue.
    Conv,
    /// Norm (+ ReLU) over channel planes, and the residual `relu(a + b)`.
    Norm,
    /// Bilinear resize.
    Resize,
    /// 2x average pooling.
    Pool,
    /// Correlation lookups (materialised pyramid and on the fly).
    Lookup,
    /// Deformable convolution's sampling.
    Deform,
    /// One ConvGRU step.
    GruStep,
    /// Convex upsampling.
    Upsample,
}

impl Op {
    /// Whether a hand-written host kernel exists.
    fn has_host_kernel(self) -> bool {
        true
    }

    /// Whether the host kernel has a backward of its own ([`crate::autodiff`]), so that training
    /// takes it too.
    fn has_host_backward(self) -> bool {
        matches!(self, Self::Conv | Self::Norm | Self::GruStep | Self::Deform | Self::Upsample)
    }

    /// The GPU formulation's route, where the operation has one.
    fn gpu_route(self) -> Option<GpuRoute> {
        match self {
            Self::Conv => Some(GpuRoute::MatmulConv),
            Self::Resize => Some(GpuRoute::Interpolate),
            Self::Lookup => Some(GpuRoute::GatheredLookup),
            Self::GruStep => Some(GpuRoute::SharedColumns),
            Self::Norm | Self::Pool | Self::Deform | Self::Upsample => None,
        }
    }
}

thread_local! {
    static PINNED: Cell<Option<Path>> = const { Cell::new(None) };
}

/// Where `op` runs on `device`.
///
/// With gradients recorded, burn's operations (their autodiff is the reference backward), except
/// on the Flex CPU device in f32 for an operation whose backward is ours ([`crate::autodiff`])
/// unless the settings say `stock-training`. On the Flex CPU device in f32 without gradients, the
/// host kernel unless the settings say `stock`. Elsewhere without
/// gradients (the GPU, or the CPU with `gpu-routes`), the GPU formulation unless its route is
/// switched off. Else burn's operation. A path pinned by [`with_path`] replaces the settings'
/// choice where the device allows it, and gives [`Path::Stock`] where it does not.
pub fn path(device: &Device, op: Op) -> Path {
    let settings = settings();
    let autodiff = device.is_autodiff();
    let cpu = *device == Device::flex();
    let host_possible =
        cpu && float_dtype(device) == FloatDType::F32 && op.has_host_kernel() && (!autodiff || op.has_host_backward());
    let host_chosen = if autodiff { settings.host_training } else { settings.host_kernels };
    let gpu_possible = !autodiff && op.gpu_route().is_some_and(|r| settings.route_enabled(r));
    match PINNED.with(Cell::get) {
        Some(Path::Host) if host_possible => Path::Host,
        Some(Path::Gpu) if gpu_possible => Path::Gpu,
        Some(_) => Path::Stock,
        None if host_possible && host_chosen => Path::Host,
        None if gpu_possible && (!cpu || settings.gpu_routes_on_cpu) => Path::Gpu,
        None => Path::Stock,
    }
}

/// Runs `f` with every operation dispatched on this thread pinned to `pinned` (where the device
/// allows it; see [`path`]); the previous pin is restored afterwards, also on a panic. Work that
/// `f` hands to other threads is dispatched by the settings as usual.
pub fn with_path<T>(pinned: Path, f: impl FnOnce() -> T) -> T {
    struct Restore(Option<Path>);
    impl Drop for Restore {
        fn drop(&mut self) {
            PINNED.with(|p| p.set(self.0));
        }
    }
    let _restore = Restore(PINNED.with(|p| p.replace(Some(pinned))));
    f()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// With the default settings: the host kernels on the f32 CPU, burn's operations under
    /// autodiff, GPU formulations only where pinned on the CPU.
    #[test]
    fn the_device_and_the_pin_choose() {
        let cpu = Device::flex();
        let ad = cpu.clone().autodiff();
        assert_eq!(path(&cpu, Op::Conv), Path::Host);
        assert_eq!(path(&ad, Op::Conv), Path::Host, "the convolution's backward is ours");
        assert_eq!(path(&ad, Op::Norm), Path::Host, "the instance norm's backward is ours");
        assert_eq!(path(&ad, Op::Resize), Path::Stock, "a resize's is burn's");
        with_path(Path::Stock, || assert_eq!(path(&ad, Op::Conv), Path::Stock));
        with_path(Path::Gpu, || {
            assert_eq!(path(&cpu, Op::Conv), Path::Gpu);
            assert_eq!(path(&cpu, Op::Upsample), Path::Stock, "no GPU formulation");
            assert_eq!(path(&ad, Op::Conv), Path::Stock, "never under autodiff");
            with_path(Path::Stock, || assert_eq!(path(&cpu, Op::Conv), Path::Stock));
            assert_eq!(path(&cpu, Op::Conv), Path::Gpu, "the outer pin is restored");
        });
        assert_eq!(path(&cpu, Op::Conv), Path::Host);
    }
}
