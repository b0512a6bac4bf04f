//! IGEV-Stereo's encoder layout (`layout = "mobilenet-pyramid"`): what it refuses and
//! what it hands on.

use burn::tensor::{Distribution, Tensor};
use dgstereo_core::tensor::max_abs_diff;
use dgstereo_core::{Probe, default_device};
use dgstereo_encoder::{DepthFeatureInput, EncoderConfig, EncoderInputs, EncoderLayout, Encoders, StereoEncoder};

fn pyramid_config() -> EncoderConfig {
    EncoderConfig { layout: EncoderLayout::MobilenetPyramid, ..Default::default() }
}

/// The pyramid takes no monocular input, refused by the `depth_features` key, and works at
/// stride 4 only, refused by the `layout` key.
#[test]
fn conflicting_options_are_refused_by_key() {
    assert!(pyramid_config().problems().is_empty());
    let added = EncoderConfig { depth_features: DepthFeatureInput::Added, ..pyramid_config() };
    let problems = added.problems();
    assert!(problems.iter().any(|p| p.key == "depth_features"), "{problems:?}");
    let e = pyramid_config().init([128; 3], 3, None, &default_device()).unwrap_err().to_string();
    assert!(e.contains("layout") && e.contains("n_downsample"), "{e}");
}

/// Both views' matching features are the 96-channel 1/4 level; the left view's pyramid (1/4 to
/// 1/32) and 1/2 stem come along, and the context has three levels of the hidden widths.
#[test]
fn the_pyramid_layout_hands_on_features_pyramid_and_context() {
    let device = default_device();
    let encoders = pyramid_config().init([32, 48, 64], 2, None, &device).unwrap();
    assert!(matches!(encoders, Encoders::Pyramid(_)));
    assert_eq!(encoders.variant_name(), "Pyramid");
    let image = || Tensor::<4>::random([1, 3, 64, 96], Distribution::Uniform(0.0, 255.0), &device);
    let (left, right) = (image(), image());
    let inputs = EncoderInputs { context_left: left.clone(), features_left: left, features_right: right, depth: None };
    let encoded = encoders.encode(inputs, 3, &mut Probe::none()).unwrap();
    assert_eq!(encoded.fmap1.dims(), [1, 96, 16, 24]);
    assert_eq!(encoded.fmap2.dims(), [1, 96, 16, 24]);
    assert!(max_abs_diff(encoded.fmap1.clone(), encoded.fmap2.clone()) > 0.0, "the views' features differ");
    let pyramid = encoded.pyramid.expect("the pyramid layout hands on the left pyramid");
    let shapes: Vec<[usize; 4]> = pyramid.levels.iter().map(|l| l.dims()).collect();
    assert_eq!(shapes, [[1, 96, 16, 24], [1, 64, 8, 12], [1, 192, 4, 6], [1, 160, 2, 3]]);
    assert_eq!(max_abs_diff(pyramid.levels[0].clone(), encoded.fmap1), 0.0);
    assert_eq!(pyramid.stem_2.dims(), [1, 32, 32, 48]);
    let context: Vec<[usize; 4]> = encoded.context.levels.iter().map(|[h, _]| h.dims()).collect();
    assert_eq!(context, [[1, 64, 16, 24], [1, 48, 8, 12], [1, 32, 4, 6]]);
}
