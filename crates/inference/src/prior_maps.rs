//! A depth prior computed elsewhere for one pair ([`crate::Engine::predict_with_prior`]).

use burn::tensor::{Device, Tensor, TensorData};
use dgstereo_core::{DepthPrior, Error, Result};
use dgstereo_data::DisparityMap;

use crate::consistency::mirror_disparity;

/// A depth prior computed elsewhere for one pair ([`crate::Engine::predict_with_prior`]): the relative
/// inverse depth (larger = nearer, any scale) of each view, at any size; the engine resizes it
/// bilinearly to the network's input, as a file prior is.
#[derive(Clone, Debug, PartialEq)]
pub struct PriorMaps {
    /// Prior of the left view.
    pub left: DisparityMap,
    /// Prior of the right view.
    pub right: DisparityMap,
}

impl PriorMaps {
    /// The maps of the mirrored, swapped pair (what the left-right check's second pass sees).
    pub(crate) fn mirrored(&self) -> Self {
        Self { left: mirror_disparity(&self.right), right: mirror_disparity(&self.left) }
    }

    /// The prior tensors at the network's input size `[height, width]`.
    pub(crate) fn at_size(&self, size: [usize; 2], device: &Device) -> DepthPrior {
        let tensor = |m: &DisparityMap| {
            let t = Tensor::<4>::from_data(TensorData::new(m.data.clone(), [1, 1, m.height, m.width]), device);
            dgstereo_kernels::resize_bilinear(t, size, true)
        };
        DepthPrior { left: tensor(&self.left), right: tensor(&self.right) }
    }

    pub(crate) fn check(&self) -> Result<()> {
        for (view, m) in [("left", &self.left), ("right", &self.right)] {
            if m.width == 0 || m.height == 0 || m.data.len() != m.width * m.height {
                let reason = format!("the {view} map is {}x{} with {} values", m.width, m.height, m.data.len());
                return Err(Error::config("prior", reason));
            }
            if let Some(bad) = m.data.iter().find(|v| !v.is_finite()) {
                return Err(Error::config("prior", format!("the {view} map holds a non-finite value ({bad})")));
            }
        }
        Ok(())
    }
}
