//! Moving a network's gradients and weights between ranks in a few large flat buffers.
//!
//! Design decision: one exchange per tensor would be hundreds of small messages a step, each
//! paying the network's latency; the gradients are instead copied, in module order, into
//! buffers of at most [`BUCKET_FLOATS`] values, summed over the ranks one buffer at a time, and
//! copied back. Every rank holds the same network, so the order and the sizes agree everywhere
//! without being exchanged.

use std::time::Instant;

use burn::module::{Module, ModuleMapper, ModuleVisitor, Param, ParamId};
use burn::optim::GradientsParams;
use burn::tensor::Tensor;
use dgstereo_collective::Collective;
use dgstereo_core::{Error, Result};

use crate::params::PathStack;

/// The most values one exchange carries (64 MiB of f32).
pub const BUCKET_FLOATS: usize = 1 << 24;

/// What summing the gradients over the ranks cost.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ExchangeCost {
    /// Wall-clock seconds of the exchanges, copies included.
    pub seconds: f64,
    /// Bytes each rank contributed.
    pub bytes: usize,
}

struct Flatten<'a> {
    grads: &'a GradientsParams,
    values: Vec<f32>,
}

impl ModuleVisitor for Flatten<'_> {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        if let Some(g) = self.grads.get::<D>(param.id) {
            self.values.extend(dgstereo_core::tensor::to_vec(g));
        }
    }
}

struct Unflatten<'a> {
    grads: &'a mut GradientsParams,
    values: &'a [f32],
    offset: usize,
}

impl ModuleVisitor for Unflatten<'_> {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let id: ParamId = param.id;
        if let Some(g) = self.grads.remove::<D>(id) {
            let dims = g.dims();
            let n = dims.iter().product::<usize>();
            let part = self.values[self.offset..self.offset + n].to_vec();
            self.offset += n;
            self.grads.register::<D>(id, dgstereo_core::tensor::from_vec(part, dims, &g.device()));
        }
    }
}

/// The gradients of `module`'s parameters that `grads` holds, one after another in module order.
pub fn flat_gradients<M: Module>(module: &M, grads: &GradientsParams) -> Vec<f32> {
    let mut flat = Flatten { grads, values: Vec::new() };
    module.visit(&mut flat);
    flat.values
}

/// `module`'s float parameters, one after another in module order.
pub fn flat_weights<M: Module>(module: &M) -> Vec<f32> {
    let mut weights = Weights { path: PathStack::default(), values: Vec::new(), ends: Vec::new() };
    module.visit(&mut weights);
    weights.values
}

/// Sums `values` over the ranks, [`BUCKET_FLOATS`] at a time.
fn all_reduce_in_buckets(ranks: &dyn Collective, values: &mut [f32]) {
    for bucket in values.chunks_mut(BUCKET_FLOATS) {
        ranks.all_reduce_sum(bucket);
    }
}

/// `grads` summed over all ranks (every rank gets the sum), with what the exchange cost. The
/// parameters are visited in `module`'s order, which is the same on every rank. In a world of
/// one the sum is `grads` itself, returned untouched at no cost.
pub fn sum_gradients<M: Module>(
    module: &M,
    grads: GradientsParams,
    ranks: &dyn Collective,
) -> (GradientsParams, ExchangeCost) {
    if ranks.size() == 1 {
        return (grads, ExchangeCost::default());
    }
    let started = Instant::now();
    let mut values = flat_gradients(module, &grads);
    all_reduce_in_buckets(ranks, &mut values);
    let mut grads = grads;
    module.visit(&mut Unflatten { grads: &mut grads, values: &values, offset: 0 });
    let cost = ExchangeCost { seconds: started.elapsed().as_secs_f64(), bytes: values.len() * size_of::<f32>() };
    (grads, cost)
}

struct Weights {
    path: PathStack,
    values: Vec<f32>,
    /// `(path, end offset)` of every parameter, to name the first one that differs.
    ends: Vec<(String, usize)>,
}

impl ModuleVisitor for Weights {
    fn enter_module(&mut self, name: &str, _container_type: &str) {
        self.path.enter(name);
    }
    fn exit_module(&mut self, _name: &str, _container_type: &str) {
        self.path.exit();
    }
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        self.values.extend(dgstereo_core::tensor::to_vec(param.val()));
        self.ends.push((self.path.current(), self.values.len()));
    }
}

struct Replace<'a> {
    values: &'a [f32],
    offset: usize,
}

impl ModuleMapper for Replace<'_> {
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let (id, value, mapper) = param.consume();
        let dims = value.dims();
        let n = dims.iter().product::<usize>();
        let part = self.values[self.offset..self.offset + n].to_vec();
        self.offset += n;
        let replaced =
            dgstereo_core::tensor::from_vec(part, dims, &value.device()).set_require_grad(value.is_require_grad());
        Param::from_mapped_value(id, replaced, mapper)
    }
}

/// What [`share_weights`] found.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct WeightCheck {
    /// The first parameter (module path) where this rank's weights differed from rank 0's, now
    /// replaced by rank 0's; `None` when they were equal bit for bit.
    pub first_difference: Option<String>,
}

/// Gives every rank rank 0's weights: rank 0's are broadcast, and each rank compares them
/// with its own bit for bit before taking them, so a caller can tell a rank that started from
/// other weights (another initialisation, another checkpoint).
pub fn share_weights<M: Module>(module: M, ranks: &dyn Collective) -> Result<(M, WeightCheck)> {
    let mut own = Weights { path: PathStack::default(), values: Vec::new(), ends: Vec::new() };
    module.visit(&mut own);
    let mut shared = own.values.clone();
    let lengths = ranks.all_gather(&[shared.len() as f64]);
    if let Some(r) = lengths.iter().position(|&n| n != shared.len() as f64) {
        let cause = format!(
            "holds a network of {} weights, rank {} one of {}: the ranks built different models",
            lengths[r],
            ranks.rank(),
            shared.len()
        );
        return Err(Error::Rank { rank: r, size: ranks.size(), cause });
    }
    for bucket in shared.chunks_mut(BUCKET_FLOATS) {
        ranks.broadcast(bucket, 0);
    }
    let differs = own.values.iter().zip(&shared).position(|(a, b)| a.to_bits() != b.to_bits());
    let Some(at) = differs else {
        return Ok((module, WeightCheck { first_difference: None }));
    };
    let name = own.ends.iter().find(|(_, end)| *end > at).map(|(p, _)| p.clone()).unwrap_or_default();
    let module = module.map(&mut Replace { values: &shared, offset: 0 });
    Ok((module, WeightCheck { first_difference: Some(name) }))
}
