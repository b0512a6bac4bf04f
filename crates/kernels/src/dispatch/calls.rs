//! The [`Call`]s of the operations whose plan needs no algorithm of its own: which paths take
//! them.

use burn::tensor::Device;

use super::{Call, Op, Path, path, products_unit};
use crate::bf16_product::Bf16Unit;
use crate::settings::Settings;

/// An operation whose host kernel takes every shape, with our backward where [`path`] gives the
/// host path under autodiff and a GPU formulation where it gives the GPU path: the resize, the
/// pooling, the lookups, convex upsampling and `relu(a + b)` (as [`Op::Norm`]).
#[derive(Debug, Clone, Copy)]
pub(crate) struct PlainCall(pub(crate) Op);

/// The correlation pyramid's all-pairs product: as [`PlainCall`]`(Op::Lookup)`, and in CPU
/// inference with bf16 products where the calling thread asks for them and the processor has a
/// unit.
#[derive(Debug, Clone, Copy)]
pub(crate) struct AllPairsCall;

/// A linear layer's product (`x · W + b` over the last axis): the host kernel only in CPU
/// inference with bf16 products, where the calling thread asks for them and the processor has a
/// unit; burn's matrix product everywhere else (it is as fast as ours in f32).
#[derive(Debug, Clone, Copy)]
pub(crate) struct LinearCall;

/// An element-wise step that has a training node of its own but no host pass for inference,
/// where it runs inside a fused kernel or as burn's operation: the ReLU ([`RECTIFY`]) and the
/// ConvGRU's gates and blend ([`NodeCall`]`(Op::GruStep)`).
#[derive(Debug, Clone, Copy)]
pub(crate) struct NodeCall(pub(crate) Op);

/// `max(0, x)`: our node in training, burn's ReLU elsewhere.
pub(crate) const RECTIFY: NodeCall = NodeCall(Op::Norm);

/// `max(0, a + b)`.
pub(crate) const ADD_RELU: PlainCall = PlainCall(Op::Norm);

/// The norms over channel planes, as the host pass and the training nodes know them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum NormKind {
    /// The instance norm.
    Instance,
    /// A per-channel affine map given as tensors (the frozen batch norm: gradients reach them).
    AffineTensors,
    /// No norm.
    Identity,
}

/// A norm over channel planes, then a ReLU when `relu`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct NormCall {
    /// The norm.
    pub(crate) kind: NormKind,
    /// Whether a ReLU follows.
    pub(crate) relu: bool,
}

/// DGIA's deformable convolution: whether the host kernel takes its geometry, and whether the
/// training node does.
#[derive(Debug, Clone, Copy)]
pub(crate) struct DeformCall<O> {
    /// The host kernel's options, where it takes the convolution and the input.
    pub(crate) host: Option<O>,
    /// The training node's options, where it takes the convolution.
    pub(crate) training: Option<O>,
}

impl Call for PlainCall {
    type Inference = ();
    type Training = ();
    type Gpu = ();
    fn op(&self) -> Op {
        self.0
    }

    fn inference(&self, _: &Settings) -> Option<()> {
        Some(())
    }

    fn training(&self, _: &Settings) -> Option<()> {
        Some(())
    }

    fn gpu(&self, _: &Settings, _: &Device) -> Option<()> {
        Some(())
    }
}

impl Call for AllPairsCall {
    type Inference = Option<Bf16Unit>;
    type Training = ();
    type Gpu = ();
    fn op(&self) -> Op {
        Op::Lookup
    }

    fn inference(&self, settings: &Settings) -> Option<Option<Bf16Unit>> {
        Some(products_unit(settings))
    }

    fn training(&self, _: &Settings) -> Option<()> {
        Some(())
    }

    fn gpu(&self, _: &Settings, _: &Device) -> Option<()> {
        Some(())
    }
}

impl Call for LinearCall {
    type Inference = Bf16Unit;
    type Training = ();
    type Gpu = ();
    fn op(&self) -> Op {
        Op::Linear
    }

    fn inference(&self, settings: &Settings) -> Option<Bf16Unit> {
        products_unit(settings)
    }

    fn training(&self, _: &Settings) -> Option<()> {
        None
    }

    fn gpu(&self, _: &Settings, _: &Device) -> Option<()> {
        None
    }
}

impl Call for NodeCall {
    type Inference = ();
    type Training = ();
    type Gpu = ();
    fn op(&self) -> Op {
        self.0
    }

    fn inference(&self, _: &Settings) -> Option<()> {
        None
    }

    fn training(&self, _: &Settings) -> Option<()> {
        Some(())
    }

    fn gpu(&self, _: &Settings, _: &Device) -> Option<()> {
        None
    }
}

impl Call for NormCall {
    type Inference = ();
    type Training = ();
    type Gpu = ();
    fn op(&self) -> Op {
        Op::Norm
    }

    fn inference(&self, _: &Settings) -> Option<()> {
        Some(())
    }

    /// The instance norm, the frozen batch norm's affine and the ReLU have nodes; no norm
    /// without a ReLU keeps burn's operations (nothing to compute).
    fn training(&self, _: &Settings) -> Option<()> {
        match self.kind {
            NormKind::Instance | NormKind::AffineTensors => Some(()),
            NormKind::Identity if self.relu => Some(()),
            NormKind::Identity => None,
        }
    }

    fn gpu(&self, _: &Settings, _: &Device) -> Option<()> {
        None
    }
}

impl<O: Copy> Call for DeformCall<O> {
    type Inference = O;
    type Training = O;
    type Gpu = ();
    fn op(&self) -> Op {
        Op::Deform
    }

    fn inference(&self, _: &Settings) -> Option<O> {
        self.host
    }

    fn training(&self, _: &Settings) -> Option<O> {
        self.training
    }

    fn gpu(&self, _: &Settings, _: &Device) -> Option<()> {
        None
    }
}

/// Whether `device` runs convolutions by the GPU's product (for the GRU step's shared columns).
pub(super) fn conv_on_gpu(device: &Device) -> bool {
    path(device, Op::Conv) == Path::Gpu
}
