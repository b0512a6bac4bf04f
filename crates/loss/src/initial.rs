//! The term of the network's initial disparity (IGEV-Stereo's soft-argmin start).
//!
//! IGEV-Stereo's `sequence_loss` supervises, beside every iteration, the disparity its geometry
//! volume starts the loop from, upsampled to full resolution by its own superpixel weights
//! (`init_disp`): `1.0 * F.smooth_l1_loss(init_disp[valid], disp_gt[valid])`, the mean over the
//! same pixels as the iterations' terms. The loop detaches its state, so this term is what trains
//! the volume's classifier and the initial superpixel heads.

use burn::tensor::Tensor;
use dgstereo_core::{Error, Result};
use serde::{Deserialize, Serialize};

/// Whether and how a sequence loss supervises the initial disparity (`initial_disparity` of a
/// `sequence-l1` loss).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum InitialDisparityTerm {
    /// Not supervised (RAFT-Stereo, DEFOM-Stereo): an initial disparity the network gives is
    /// ignored.
    #[default]
    None,
    /// IGEV-Stereo's: smooth L1 (`beta = 1`) against the ground truth with weight 1, averaged
    /// over the supervised pixels, added to the iterations' terms.
    SmoothL1,
}

impl InitialDisparityTerm {
    /// Both terms, in the order of the enum.
    pub const ALL: [Self; 2] = [Self::None, Self::SmoothL1];

    /// The name the TOML key `initial_disparity` writes.
    pub fn name(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::SmoothL1 => "smooth-l1",
        }
    }

    /// Whether the loss reads the network's initial disparity.
    pub fn needs_initial(self) -> bool {
        self == Self::SmoothL1
    }

    /// The initial disparity this term reads from `initial` (none for [`Self::None`]), checked
    /// against the ground truth's shape `dims`.
    ///
    /// # Errors
    /// [`Error::Config`] keyed `loss.initial_disparity` when the term needs an initial disparity
    /// and the network gave none; [`Error::Shape`] when its shape is not the ground truth's.
    pub fn input(self, initial: Option<&Tensor<4>>, dims: [usize; 4]) -> Result<Option<&Tensor<4>>> {
        if !self.needs_initial() {
            return Ok(None);
        }
        let initial = initial.ok_or_else(|| {
            Error::config(
                "loss.initial_disparity",
                format!(
                    "\"{}\" supervises the network's initial disparity at full resolution, and the network gave \
                     none: only IGEV-Stereo's start (model.initial_disparity kind = \"soft-argmin\" with \
                     model.updater.upsampling = \"superpixel\") has one",
                    self.name()
                ),
            )
        })?;
        if initial.dims() != dims {
            return Err(Error::Shape(format!(
                "loss: the initial disparity is {:?} but the ground truth is {dims:?}",
                initial.dims()
            )));
        }
        Ok(Some(initial))
    }
}

/// PyTorch's `smooth_l1_loss` per element with `beta = 1`: `0.5 x^2` where `|x| < 1`, else
/// `|x| - 0.5` (continuous, with gradient `x` inside and `sign(x)` outside).
///
/// # Shapes
/// - `difference`: any; output: the same
pub fn smooth_l1(difference: Tensor<4>) -> Tensor<4> {
    let magnitude = difference.clone().abs();
    let inside = magnitude.clone().lower_elem(1.0);
    let quadratic = (difference.clone() * difference).mul_scalar(0.5);
    magnitude.sub_scalar(0.5).mask_where(inside, quadratic)
}
