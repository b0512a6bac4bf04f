//! IGEV-Stereo's superpixel upsampling in the pass: the logits of each iteration's weights from
//! the update block's mask feature and the left image stem, and the soft-argmin start with its
//! own upsampled disparity (returned in training, as the reference's `init_disp`, and traced).

use burn::tensor::activation::softmax;
use burn::tensor::{FloatDType, Tensor};
use dgstereo_core::Probe;
use dgstereo_core::tensor::cast_float;
use dgstereo_encoder::FeaturePyramid;
use dgstereo_updater::context_upsample;

use crate::RaftStereo;
use crate::network::{UpdateGrid, state_of_flow};

impl RaftStereo {
    /// The superpixel weights' logits (`spx_gru(spx_2_gru(mask, stem_2))`, `[N, 9, H, W]`) of
    /// the mask feature `mask`, `None` for a model without the superpixel upsampling.
    pub(crate) fn superpixel_logits(&self, mask: Tensor<4>, grid: &UpdateGrid) -> Option<Tensor<4>> {
        let (upsampler, stem_2) = (self.superpixel.as_ref()?, grid.stem_2.as_ref()?);
        Some(upsampler.spx_gru.forward(upsampler.spx_2_gru.forward(mask, stem_2.clone())))
    }

    /// The loop's start from the geometry volume's logits `logits` (`[N, D, H/4, W/4]`): no
    /// state when the initialiser does not read them. With `upsample` (training) or when
    /// tracing, the initial disparity is also upsampled by the initial superpixel weights
    /// (`superpixel.spx_4`, `.spx_2`, `.spx`; the reference's `init_disp`, which its loss
    /// supervises); tracing records that path and the result (`initial_disparity_up`).
    ///
    /// # Errors
    /// [`dgstereo_core::Error::Config`] from the initialiser.
    pub(crate) fn geometry_initial(
        &self,
        logits: &Tensor<4>,
        pyramid: &FeaturePyramid,
        upsample: bool,
        probe: &mut Probe<'_>,
    ) -> dgstereo_core::Result<GeometryStart> {
        let none = GeometryStart { state: None, upsampled: None };
        if !self.initial_disparity.needs_geometry() {
            return Ok(none);
        }
        let Some(disparity) =
            probe.time("initial disparity", || self.initial_disparity.disparity(None, Some(logits)))?
        else {
            return Ok(none);
        };
        let disparity = cast_float(disparity, FloatDType::F32);
        probe.record("initial_disparity", &disparity);
        let upsampled = match (upsample || probe.tracing(), &self.superpixel) {
            (true, Some(upsampler)) => {
                let spx_4 = upsampler.spx_4.forward(pyramid.levels[0].clone());
                let spx_2 = upsampler.spx_2.forward(spx_4.clone(), pyramid.stem_2.clone());
                let spx = upsampler.spx.forward(spx_2.clone());
                let up = context_upsample(disparity.clone(), softmax(cast_float(spx.clone(), FloatDType::F32), 1));
                probe.record("superpixel.spx_4", &spx_4);
                probe.record("superpixel.spx_2", &spx_2);
                probe.record("superpixel.spx", &spx);
                probe.record("initial_disparity_up", &up);
                upsample.then_some(up)
            }
            _ => None,
        };
        // The loop's state of the x flow `-d`.
        Ok(GeometryStart { state: Some(state_of_flow(self.motion, disparity.neg())), upsampled })
    }
}

/// Where the geometry volume starts the loop ([`RaftStereo::geometry_initial`]).
pub(crate) struct GeometryStart {
    /// The loop's initial state (the motion's convention), `None` when the initialiser does not
    /// read the volume.
    pub(crate) state: Option<Tensor<4>>,
    /// The initial positive disparity at full resolution, when asked for and the network has
    /// the superpixel heads.
    pub(crate) upsampled: Option<Tensor<4>>,
}
