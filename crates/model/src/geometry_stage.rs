//! Stage 2 of IGEV-Stereo's pass: the geometry encoding volume, built from the left feature
//! pyramid and the right view's finest features, and the lookup that joins it with the all-pairs
//! correlation of the match features ([`Correlation::Geometry`]).
//!
//! The volume's classifier logits are what the soft-argmin initialiser reads
//! ([`crate::InitialDisparity::SoftArgmin`]); as in the reference's mixed precision, the lookup's
//! tensors are f32 (its `.float()` before `Combined_Geo_Encoding_Volume`).

use burn::tensor::{FloatDType, Tensor};
use dgstereo_core::Probe;
use dgstereo_core::tensor::cast_float;
use dgstereo_costvolume::{CombinedGeometryVolume, Correlation, CorrelationImplementation, GeometryEncoding};

use crate::RaftStereo;

impl RaftStereo {
    /// The geometry encoding volume of the left pyramid `left` (finest first) against the right
    /// view's finest features `right`, as the lookup of the update loop (its correlation half
    /// stored or on the fly, as `implementation` says), and the classifier's logits
    /// (`[N, D, H/4, W/4]`).
    pub(crate) fn geometry_volume(
        &self,
        geometry: &GeometryEncoding,
        left: &[Tensor<4>],
        right: Tensor<4>,
        implementation: CorrelationImplementation,
        probe: &mut Probe<'_>,
    ) -> (Correlation, Tensor<4>) {
        let out = probe.time("geometry volume", || geometry.forward(left, right));
        if probe.tracing() {
            let flat = |v: &Tensor<5>| {
                let [n, c, d, h, w] = v.dims();
                v.clone().reshape([n, c * d, h, w])
            };
            probe.record("geometry.corr_stem", &flat(&out.corr_stem));
            probe.record("geometry.corr_feature_att", &flat(&out.corr_feature_att));
            probe.record("geometry.cost_agg", &flat(&out.volume));
            probe.record("geometry.classifier", &out.logits);
        }
        let f32 = |t: Tensor<4>| cast_float(t, FloatDType::F32);
        let c = &self.correlation;
        let lookup = probe.time("correlation build", || {
            CombinedGeometryVolume::new(
                f32(out.match_left),
                f32(out.match_right),
                cast_float(out.volume, FloatDType::F32),
                c.levels,
                c.radius,
                implementation,
            )
        });
        (Correlation::Geometry(lookup), out.logits)
    }
}
