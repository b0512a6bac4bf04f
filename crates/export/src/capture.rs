//! Recording the inference forward pass on burn's capture device: the model's own
//! `padded_disparities` (padding, forward, crop, sign), so the file computes what `infer
//! --min-size off` does.

use burn::backend::capture::{CaptureBackend, CapturedGraph, TensorId};
use burn::module::Module;
use burn::tensor::{Device, Tensor};
use dgstereo_core::{DepthPrior, Error, Result};
use dgstereo_costvolume::CorrelationImplementation;
use dgstereo_model::inference::padded_disparities;
use dgstereo_model::{ForwardOptions, Probe, StereoModel, Trace};

use crate::lower::Boundaries;

/// A recorded forward pass with the names of its inputs and outputs.
pub struct Captured {
    /// The burn-ir graph and the values it read (weights, constants).
    pub graph: CapturedGraph,
    /// The runtime inputs and the outputs, named.
    pub boundaries: Boundaries,
    /// `(tensor, name)` of the named activations of the forward pass (`fnet.left`,
    /// `context.hidden.0`, `iter.3.corr`, ...), by which an error places an operation.
    pub landmarks: Vec<(TensorId, String)>,
}

fn id_of(t: &Tensor<4>) -> Result<TensorId> {
    t.clone()
        .try_into_primitive::<CaptureBackend>()
        .map(|p| p.id())
        .map_err(|e| Error::Internal(format!("a tensor is not on the capture device: {e:?}")))
}

/// The forward pass of `model` on one `[1, 3, height, width]` pair (and its prior maps, where
/// the model takes them), `iters` iterations, recorded with the all-pairs cost volume.
pub fn capture_disparity(model: &StereoModel, height: usize, width: usize, iters: usize) -> Result<Captured> {
    let device = Device::capture();
    let host = Device::flex();
    let with_prior = model.config.needs_prior();
    let mut outcome = None;
    let mut trace = Trace::new();
    let graph = device.capture_scope(|scope| {
        let mut run = || -> Result<Boundaries> {
            let network = model.network.clone().to_device(&device);
            let image = || Tensor::<4>::zeros([1, 3, height, width], &host).to_device(&device);
            let map = || Tensor::<4>::zeros([1, 1, height, width], &host).to_device(&device);
            let (left, right) = (image(), image());
            let mut inputs = vec![(id_of(&left)?, "left".to_string()), (id_of(&right)?, "right".to_string())];
            let prior = if with_prior {
                let prior = DepthPrior { left: map(), right: map() };
                inputs.push((id_of(&prior.left)?, "left_prior".to_string()));
                inputs.push((id_of(&prior.right)?, "right_prior".to_string()));
                Some(prior)
            } else {
                None
            };
            let options = ForwardOptions {
                implementation: Some(CorrelationImplementation::Reg),
                probe: Probe::new(Some(&mut trace), None),
                ..ForwardOptions::default()
            };
            let out = padded_disparities(&network, &model.config, left, right, prior.as_ref(), iters, options)?;
            let last = out.last().ok_or_else(|| Error::Internal("the forward pass gave no disparity".into()))?;
            Ok(Boundaries { inputs, outputs: vec![(id_of(last)?, "disparity".to_string())] })
        };
        match run() {
            Ok(boundaries) => {
                let inputs: Vec<TensorId> = boundaries.inputs.iter().map(|(id, _)| *id).collect();
                let outputs: Vec<TensorId> = boundaries.outputs.iter().map(|(id, _)| *id).collect();
                outcome = Some(Ok(boundaries));
                scope.complete(inputs, outputs)
            }
            Err(e) => {
                outcome = Some(Err(e));
                scope.complete([], [])
            }
        }
    });
    let boundaries = outcome.ok_or_else(|| Error::Internal("the capture did not run".into()))??;
    let graph = graph.map_err(|e| Error::Internal(format!("recording the forward pass: {e}")))?;
    let landmarks = trace.iter().map(|(name, t)| Ok((id_of(t)?, name.clone()))).collect::<Result<_>>()?;
    Ok(Captured { graph, boundaries, landmarks })
}
