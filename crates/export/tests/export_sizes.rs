//! Every size `infer` accepts exports: widths and heights 32..256 in steps of 16, for the bundled
//! default (1/8 resolution, padded to 64, whose correlation pyramid pools the narrowest pairs
//! below one column) and RAFT-Stereo's default architecture (1/4 resolution, padded to 32). Each
//! size is recorded and lowered to ONNX (one iteration: the shapes do not depend on the count);
//! ONNX Runtime runs a few exported sizes in `bindings/python/tests/test_onnx_export.py`.
//! Sizes under the minimum are an error naming the size.

use dgstereo_export::capture::capture_disparity;
use dgstereo_export::lower::lower_graph;
use dgstereo_export::{MIN_SIDE, export_onnx};
use dgstereo_inference::working_size::MIN_WORKING_SIZE;
use dgstereo_inference::{Engine, EngineConfig};
use dgstereo_model::{ModelConfig, StereoModel};

/// The output's shape in the lowered graph, for a pair of `height x width`.
fn exported_output_shape(model: &StereoModel, height: usize, width: usize) -> Vec<i64> {
    let captured = capture_disparity(model, height, width, 1)
        .unwrap_or_else(|e| panic!("{height}x{width}: the capture fails: {e}"));
    let proto = lower_graph(
        &captured.graph.graph.operations,
        &captured.graph.values,
        &captured.boundaries,
        &captured.landmarks,
        "test",
    )
    .unwrap_or_else(|e| panic!("{height}x{width}: the lowering fails: {e}"));
    let output = &proto.graph.output[0];
    output.type_.tensor_type().shape.as_ref().map(|s| s.dim.iter().map(|d| d.dim_value()).collect()).unwrap_or_default()
}

fn sizes() -> impl Iterator<Item = (usize, usize)> {
    (32..=256).step_by(16).flat_map(|h| (32..=256).step_by(16).map(move |w| (h, w)))
}

#[test]
fn the_bundled_default_exports_at_every_size_infer_accepts() {
    let engine = Engine::load(&EngineConfig::default()).unwrap();
    assert_eq!(engine.model_config().factor(), 8);
    for (h, w) in sizes() {
        assert_eq!(exported_output_shape(engine.stereo_model(), h, w), [1, 1, h as i64, w as i64], "{h}x{w}");
    }
}

#[test]
fn raft_stereos_default_architecture_exports_at_every_size_infer_accepts() {
    let device = burn::tensor::Device::flex();
    let config = ModelConfig::default();
    let model = StereoModel::new(config.init(&device).unwrap(), config, device);
    for (h, w) in sizes() {
        assert_eq!(exported_output_shape(&model, h, w), [1, 1, h as i64, w as i64], "{h}x{w}");
    }
}

#[test]
fn sizes_under_the_minimum_are_errors_naming_the_size() {
    assert_eq!(MIN_SIDE, MIN_WORKING_SIZE, "export and infer accept the same sizes");
    let engine = Engine::load(&EngineConfig::default()).unwrap();
    for (h, w) in [(31, 64), (64, 16), (1, 1), (0, 64)] {
        let e = export_onnx(engine.stereo_model(), h, w, 1).unwrap_err();
        assert!(e.to_string().contains(&format!("{h}x{w}")) && e.to_string().contains("32"), "{e}");
    }
    // The smallest size is a whole file whose output has the pair's size.
    let exported = export_onnx(engine.stereo_model(), 32, 32, 1).unwrap();
    assert_eq!(exported.outputs, [("disparity".to_string(), vec![1, 1, 32, 32])]);
}
