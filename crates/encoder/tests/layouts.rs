//! Every encoder layout through one body generic over the stage trait [`StereoEncoder`]: the
//! shapes it promises at stride 4, finite values, and the error for missing monocular features.

use burn::tensor::{Distribution, Tensor};
use dgstereo_core::tensor::to_vec;
use dgstereo_core::{Error, Probe, default_device};
use dgstereo_encoder::{DepthFeatureInput, EncoderConfig, EncoderInputs, EncoderLayout, Encoders, StereoEncoder};

const H: usize = 64;
const W: usize = 96;
const LEVELS: usize = 3;

fn finite(t: &Tensor<4>) -> bool {
    to_vec(t.clone()).iter().all(|v| v.is_finite())
}

/// Both views' features at 1/4 with one width, `LEVELS` context levels at 1/4, 1/8, 1/16 with
/// both heads at their level's size, every value finite; an encoder that adds monocular
/// features refuses to run without them, keyed `encoder.depth_features`.
fn conforms<E: StereoEncoder>(encoder: &E, name: &str) {
    let device = default_device();
    let image = || Tensor::<4>::random([1, 3, H, W], Distribution::Uniform(0.0, 255.0), &device);
    let left = image();
    let inputs =
        EncoderInputs { context_left: left.clone(), features_left: left, features_right: image(), depth: None };
    let encoded = encoder.encode(inputs, LEVELS, &mut Probe::none());
    if encoder.takes_depth_features() {
        match encoded {
            Err(Error::Config(problem)) => assert_eq!(problem.key, "encoder.depth_features", "{name}"),
            other => panic!("{name} runs without the monocular features it adds: {:?}", other.map(|e| e.fmap1.dims())),
        }
        return;
    }
    let encoded = encoded.unwrap_or_else(|e| panic!("{name}: {e}"));
    let [n, c, h, w] = encoded.fmap1.dims();
    assert_eq!([n, h, w], [1, H / 4, W / 4], "{name}");
    assert_eq!(encoded.fmap2.dims(), [1, c, H / 4, W / 4], "{name}");
    assert!(finite(&encoded.fmap1) && finite(&encoded.fmap2), "{name}: a feature is not finite");
    assert_eq!(encoded.context.levels.len(), LEVELS, "{name}");
    for (i, heads) in encoded.context.levels.iter().enumerate() {
        for head in heads {
            assert_eq!(head.dims()[2..], [(H / 4) >> i, (W / 4) >> i], "{name}, level {i}");
            assert!(finite(head), "{name}, level {i}: a context value is not finite");
        }
    }
}

#[test]
fn every_layout_keeps_the_stage_contract() {
    let device = default_device();
    let config = |layout| EncoderConfig { layout, trunk_dims: [16, 16, 24], feature_dim: 32, ..Default::default() };
    for layout in EncoderLayout::ALL {
        let encoders = config(layout).init([16; 3], 2, None, &device).unwrap();
        let name = encoders.variant_name();
        match &encoders {
            Encoders::Separate(e) => conforms(e, name),
            Encoders::Shared(e) => conforms(e, name),
            Encoders::Pyramid(e) => conforms(e, name),
        }
        conforms(&encoders, &format!("Encoders::{name}"));
    }
    // DEFOM-Stereo's separate encoders, which add 8 channels of monocular features.
    let added = EncoderConfig { depth_features: DepthFeatureInput::Added, ..config(EncoderLayout::Separate) };
    conforms(&added.init([16; 3], 2, Some(8), &device).unwrap(), "separate, monocular features added");
}
