//! The one place that decides how an operation is computed.
//!
//! Every operation of the face asks `plan` once and carries out the `Plan` it gets; no
//! other code looks at the device, the settings or a shape threshold to choose a kernel. The
//! choice depends on the device (the Flex CPU backend or another), its float dtype, whether it
//! records gradients, the process's [`Settings`], the operation's
//! shape and, for a convolution, the [`Numerics`] its caller asks for. [`path`] is the coarse
//! half of it (host, GPU formulation or burn's operation, from the device and the settings);
//! each operation's `Call` gives the fine half (which algorithm on that path, or none where
//! the path does not take the shape). Tests and comparisons can pin a path for a closure on the
//! calling thread ([`with_path`]), which is how one test body runs on every path
//! ([`crate::test_paths!`]).

use std::cell::Cell;

use burn::tensor::{Device, FloatDType};
use dgstereo_core::device::float_dtype;

use crate::bf16_product::Bf16Unit;
use crate::settings::{GpuRoute, Settings, settings};

mod calls;
mod conv;
mod product_forms;

pub(crate) use calls::{
    ADD_RELU, AllPairsCall, DeformCall, LinearCall, NodeCall, NormCall, NormKind, PlainCall, RECTIFY,
};
pub(crate) use conv::{ConvCall, GruStepCall, host_algorithm};
#[cfg(test)]
pub(crate) use conv::{TRAINING_WINOGRAD_MIN_CHANNELS, training_algorithms, winograd_tile};

/// Where an operation is computed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Path {
    /// Hand-written host code: inference, and training of the operations whose backward is
    /// ours, on the Flex CPU backend in f32.
    Host,
    /// burn's operations arranged for fewer kernel launches: GPU inference.
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
    /// A linear layer's product over the last axis (the ViT's projections): a host kernel only
    /// for bf16 products, burn's matrix product otherwise.
    Linear,
}

impl Op {
    /// Whether a hand-written host kernel exists for inference (each operation's [`Call`] says
    /// which shapes it takes).
    fn has_host_kernel(self) -> bool {
        match self {
            Self::Conv
            | Self::Norm
            | Self::Resize
            | Self::Pool
            | Self::Lookup
            | Self::Deform
            | Self::GruStep
            | Self::Upsample
            | Self::Linear => true,
        }
    }

    /// Whether the host kernel has a backward of its own (`crate::autodiff`), so that training
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
            Self::Norm | Self::Pool | Self::Deform | Self::Upsample | Self::Linear => None,
        }
    }
}

/// How much a convolution's rounding may change in the training forward: an explicit argument
/// of every convolution of the face, given by the stage that knows what follows the layer.
///
/// Winograd's sums differ from plain products in rounding, and an instance or group norm after
/// a layer divides by that layer's own statistics, which magnifies the difference (the official
/// training step's check fails on the feature encoder's gradients when its layers take
/// Winograd). A convolution cannot see what follows it, so its caller says. Inference takes
/// Winograd wherever it suits regardless.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Numerics {
    /// A norm that divides by the activations' own statistics may follow, directly or later:
    /// the training forward keeps plain products below 256 input channels.
    #[default]
    Sensitive,
    /// Nothing after the layer magnifies a change of rounding (the update loop; an encoder with
    /// frozen batch norms or none): the training forward takes Winograd wherever it suits.
    Tolerant,
}

/// What the dispatch decided for one call: the path and, on it, the algorithm.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Plan<I, T = (), G = ()> {
    /// CPU inference: the host kernel, by algorithm `I`.
    HostInference(I),
    /// CPU training: the node with our backward, by algorithm `T`.
    HostTraining(T),
    /// GPU inference: the launch-saving formulation `G`.
    Gpu(G),
    /// burn's operations (or, for a composite operation, the composition of face operations).
    Stock,
}

/// One call of an operation as the dispatch sees it: which operation, and which algorithm each
/// path would take for its shape (`None` where that path does not take it).
pub(crate) trait Call {
    /// The host kernel's algorithm in inference.
    type Inference;
    /// The algorithm of the node with our backward in training.
    type Training;
    /// The GPU formulation.
    type Gpu;
    /// The operation.
    fn op(&self) -> Op;
    /// The host kernel's algorithm for CPU inference, or `None` where it does not take the call.
    fn inference(&self, settings: &Settings) -> Option<Self::Inference>;
    /// The training node's algorithm, or `None` where burn's autodiff runs the call.
    fn training(&self, settings: &Settings) -> Option<Self::Training>;
    /// The GPU formulation, or `None` where burn's operation runs the call.
    fn gpu(&self, settings: &Settings, device: &Device) -> Option<Self::Gpu>;
}

/// The whole choice for `call` on `device`: [`path`] from the device and the settings, then, on
/// that path, the algorithm the call's shape takes, or [`Plan::Stock`] where none does.
pub(crate) fn plan<C: Call>(device: &Device, call: &C) -> Plan<C::Inference, C::Training, C::Gpu> {
    let settings = settings();
    let plan = match path(device, call.op()) {
        Path::Host if device.is_autodiff() => call.training(settings).map(Plan::HostTraining),
        Path::Host => call.inference(settings).map(Plan::HostInference),
        Path::Gpu => call.gpu(settings, device).map(Plan::Gpu),
        Path::Stock => None,
    };
    plan.unwrap_or(Plan::Stock)
}

/// Whether `device` records operations instead of running them (burn's capture device).
pub fn is_capture(device: &Device) -> bool {
    matches!(device.as_dispatch(), burn::backend::DispatchDevice::Capture(_))
}

thread_local! {
    static PINNED: Cell<Option<Path>> = const { Cell::new(None) };
    static PRODUCTS: Cell<ProductPrecision> = const { Cell::new(ProductPrecision::F32) };
}

/// The precision of the host kernels' matrix products in CPU inference on the calling thread
/// ([`with_products`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum ProductPrecision {
    /// f32 inputs and sums: the reference.
    #[default]
    F32,
    /// bf16 inputs (weights converted once, activations at each product's input) with f32 sums,
    /// on the processor's bf16 unit ([`bf16_unit`]); f32 where the processor has none. Norms,
    /// activations, lookups, resizes and everything outside the products stay f32.
    Bf16,
}

/// Runs `f` with the host kernels' products on this thread in `precision` (the plans made on
/// this thread decide; a plan carries its precision to the threads that run it). The previous
/// precision is restored afterwards, also on a panic.
pub fn with_products<T>(precision: ProductPrecision, f: impl FnOnce() -> T) -> T {
    struct Restore(ProductPrecision);
    impl Drop for Restore {
        fn drop(&mut self) {
            PRODUCTS.with(|p| p.set(self.0));
        }
    }
    let _restore = Restore(PRODUCTS.with(|p| p.replace(precision)));
    f()
}

/// The precision of the products on this thread.
pub fn product_precision() -> ProductPrecision {
    PRODUCTS.with(Cell::get)
}

/// The name of the bf16 unit the products take in [`ProductPrecision::Bf16`] on this processor
/// with the process's settings (`amx-bf16` or `avx512-bf16`), `None` where it has none.
pub fn bf16_unit() -> Option<&'static str> {
    best_bf16_unit(settings()).map(Bf16Unit::name)
}

/// The fastest bf16 unit the processor has and the settings allow.
fn best_bf16_unit(settings: &Settings) -> Option<Bf16Unit> {
    Bf16Unit::ALL.into_iter().filter(|&u| settings.amx || u != Bf16Unit::Tiles).find(|u| u.available())
}

/// The bf16 unit of the products planned on this thread: `None` in f32 or where the processor
/// has none.
fn products_unit(settings: &Settings) -> Option<Bf16Unit> {
    (product_precision() == ProductPrecision::Bf16).then(|| best_bf16_unit(settings)).flatten()
}

/// Where `op` runs on `device`: the coarse half of `plan`.
///
/// With gradients recorded, burn's operations (their autodiff is the reference backward), except
/// on the Flex CPU device in f32 for an operation whose backward is ours (`crate::autodiff`)
/// unless the settings say `stock-training`. On the Flex CPU device in f32 without gradients, the
/// host kernel unless the settings say `stock`. Elsewhere without gradients (the GPU, or the CPU
/// with `gpu-routes`), the GPU formulation unless its route is switched off. Else burn's
/// operation. A path pinned by [`with_path`] replaces the settings' choice where the device
/// allows it, and gives [`Path::Stock`] where it does not.
pub fn path(device: &Device, op: Op) -> Path {
    let settings = settings();
    // A capture device records burn's operations for an exporter: only burn's own, no kernel.
    if is_capture(device) {
        return Path::Stock;
    }
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

    /// On burn's capture device (the ONNX exporter's) every operation is burn's own, whatever
    /// the pin: a recorded graph holds burn-ir operations only.
    #[test]
    fn the_capture_device_takes_burns_operations() {
        let capture = Device::capture();
        for op in [Op::Conv, Op::Norm, Op::Resize, Op::Pool, Op::Lookup, Op::Deform, Op::GruStep, Op::Upsample] {
            assert_eq!(path(&capture, op), Path::Stock, "{op:?}");
            with_path(Path::Gpu, || assert_eq!(path(&capture, op), Path::Stock, "{op:?} pinned"));
        }
    }

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

    /// The simple operations' plans: the host pass for inference, our node in training where the
    /// operation has one, burn's operations elsewhere.
    #[test]
    fn simple_operations_plan_by_device() {
        let cpu = Device::flex();
        let ad = cpu.clone().autodiff();
        assert_eq!(plan(&cpu, &PlainCall(Op::Resize)), Plan::HostInference(()));
        assert_eq!(plan(&ad, &PlainCall(Op::Resize)), Plan::Stock);
        assert_eq!(plan(&ad, &PlainCall(Op::Upsample)), Plan::HostTraining(()));
        assert_eq!(plan(&cpu, &RECTIFY), Plan::Stock, "inference folds its ReLUs into the kernels");
        assert_eq!(plan(&ad, &RECTIFY), Plan::HostTraining(()));
        let identity = NormCall { kind: NormKind::Identity, relu: false };
        assert_eq!(plan(&ad, &identity), Plan::Stock, "nothing to compute");
        assert_eq!(plan(&cpu, &identity), Plan::HostInference(()));
        let affine = NormCall { kind: NormKind::AffineTensors, relu: true };
        assert_eq!(plan(&ad, &affine), Plan::HostTraining(()), "the frozen batch norm's node");
        with_path(Path::Gpu, || {
            assert_eq!(plan(&cpu, &PlainCall(Op::Resize)), Plan::Gpu(()));
            assert_eq!(plan(&cpu, &PlainCall(Op::Pool)), Plan::Stock);
        });
    }
}
