//! IGEV-Stereo's superpixel upsampling in the pass: the logits of each iteration's weights from
//! the update block's mask feature and the left image stem, and the soft-argmin start with its
//! own upsampled disparity (traced, as the reference returns it in training).

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

    /// The loop's initial state from the geometry volume's logits `logits` (`[N, D, H/4, W/4]`),
    /// `None` when the initialiser does not read them. When tracing, it also records the
    /// initial superpixel weights' path (`superpixel.spx_4`, `.spx_2`, `.spx`) and the initial
    /// disparity upsampled by them (`initial_disparity_up`).
    ///
    /// # Errors
    /// [`dgstereo_core::Error::Config`] from the initialiser.
    pub(crate) fn geometry_initial(
        &self,
        logits: &Tensor<4>,
        pyramid: &FeaturePyramid,
        probe: &mut Probe<'_>,
    ) -> dgstereo_core::Result<Option<Tensor<4>>> {
        if !self.initial_disparity.needs_geometry() {
            return Ok(None);
        }
        let Some(disparity) =
            probe.time("initial disparity", || self.initial_disparity.disparity(None, Some(logits)))?
        else {
            return Ok(None);
        };
        let disparity = cast_float(disparity, FloatDType::F32);
        probe.record("initial_disparity", &disparity);
        if let (true, Some(upsampler)) = (probe.tracing(), &self.superpixel) {
            let spx_4 = upsampler.spx_4.forward(pyramid.levels[0].clone());
            let spx_2 = upsampler.spx_2.forward(spx_4.clone(), pyramid.stem_2.clone());
            let spx = upsampler.spx.forward(spx_2.clone());
            let up = context_upsample(disparity.clone(), softmax(cast_float(spx.clone(), FloatDType::F32), 1));
            probe.record("superpixel.spx_4", &spx_4);
            probe.record("superpixel.spx_2", &spx_2);
            probe.record("superpixel.spx", &spx);
            probe.record("initial_disparity_up", &up);
        }
        // The loop's state of the x flow `-d`.
        Ok(Some(state_of_flow(self.motion, disparity.neg())))
    }
}
