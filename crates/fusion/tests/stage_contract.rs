//! Every fusion through one body generic over the stage trait [`ImageFusion`]: the shape and
//! range the trait promises with the prior, and without it either the same promise or the error
//! keyed `fusion.kind`.

use burn::tensor::{Distribution, Tensor};
use dgstereo_core::tensor::to_vec;
use dgstereo_core::{Error, default_device};
use dgstereo_fusion::{ConvFusion, DeformableFusion, FusionConfig, IdentityFusion, ImageFusion};

const SIZE: [usize; 4] = [2, 3, 12, 16];

/// The enhanced image of `fusion` is `[N, 3, H, W]` and finite, with the prior; without it, the
/// same or an error keyed `fusion.kind`, as `needs_prior` says.
fn conforms<F: ImageFusion>(fusion: &F, needs_prior: bool, name: &str) {
    let device = default_device();
    let image = || Tensor::<4>::random(SIZE, Distribution::Uniform(0.0, 255.0), &device);
    let depth = Tensor::<4>::random([SIZE[0], 1, SIZE[2], SIZE[3]], Distribution::Uniform(0.0, 5.0), &device);
    let fused = fusion.fuse(image(), Some(depth)).unwrap_or_else(|e| panic!("{name}: {e}"));
    assert_eq!(fused.dims(), SIZE, "{name}");
    assert!(to_vec(fused).iter().all(|v| v.is_finite()), "{name}: a value is not finite");
    match (fusion.fuse(image(), None), needs_prior) {
        (Ok(fused), false) => assert_eq!(fused.dims(), SIZE, "{name}"),
        (Err(Error::Config(problem)), true) => assert_eq!(problem.key, "fusion.kind", "{name}"),
        (Ok(_), true) => panic!("{name} needs the prior but ran without it"),
        (Err(e), _) => panic!("{name} failed without the prior: {e}"),
    }
}

#[test]
fn every_fusion_keeps_the_stage_contract() {
    let device = default_device();
    conforms(&IdentityFusion, false, "identity");
    conforms(&DeformableFusion::new(8, &device).unwrap(), true, "deformable");
    conforms(&ConvFusion::new(4, &device).unwrap(), true, "conv");
    for config in FusionConfig::variants() {
        conforms(&config.init(&device).unwrap(), config.needs_prior(), config.kind());
    }
}
