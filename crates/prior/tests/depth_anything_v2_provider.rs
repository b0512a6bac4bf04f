//! The `depth-anything-v2` provider on a randomly initialised ViT-S, and its errors (the golden
//! checkpoint is checked in `depth_anything_v2_golden.rs`).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use burn::tensor::{Distribution, Tensor};
use dgstereo_core::tensor::{max_abs_diff, to_vec};
use dgstereo_prior::depth_anything::preprocess::{network_input_size, preprocess};
use dgstereo_prior::safetensors_io::{FloatArray, write_float_tensors};
use dgstereo_prior::{
    DepthAnythingV2, DepthAnythingV2Encoder, DepthAnythingV2Prior, PriorConfig, PriorInput, PriorProvider,
    verify_depth_anything_v2,
};

#[test]
fn both_views_run_in_one_batch_and_come_back_at_image_size() {
    let device = dgstereo_core::default_device();
    burn::tensor::Device::seed(&device, 9);
    let model = DepthAnythingV2::new(DepthAnythingV2Encoder::Vits, &device);
    let (h, w, input_size) = (20, 31, 28);
    assert_eq!(network_input_size(h, w, input_size).unwrap(), [28, 42]);
    let left = Tensor::<4>::random([2, 3, h, w], Distribution::Uniform(0.0, 255.0), &device);
    let right = Tensor::<4>::random([2, 3, h, w], Distribution::Uniform(0.0, 255.0), &device);

    let prior = DepthAnythingV2Prior::new(model, input_size);
    let input = PriorInput { left: left.clone(), right: right.clone(), gt_disparity: None, names: vec![] };
    let out = prior.provide(&input).unwrap().expect("a prior");
    assert_eq!(out.left.dims(), [2, 1, h, w]);
    assert_eq!(out.right.dims(), [2, 1, h, w]);
    assert!(to_vec(out.left.clone()).iter().all(|v| v.is_finite() && *v >= 0.0));

    // Same as running each view alone: batching must not mix the views.
    let alone = prior.model().infer(right.clone(), input_size).unwrap();
    assert!(max_abs_diff(alone, out.right.clone()) < 1e-4);
    let first = prior.model().infer(left.narrow(0, 0, 1), input_size).unwrap();
    assert!(max_abs_diff(first, out.left.narrow(0, 0, 1)) < 1e-4);

    // The network input has the documented size and ImageNet statistics of a grey image.
    let grey = Tensor::<4>::full([1, 3, h, w], 127.5, &device);
    let x = preprocess(grey, input_size).unwrap();
    assert_eq!(x.dims(), [1, 3, 28, 42]);
    let v = to_vec(x);
    let expected_red = (0.5 - 0.485) / 0.229;
    assert!((v[0] - expected_red).abs() < 1e-5, "{} vs {expected_red}", v[0]);
}

#[test]
fn a_missing_checkpoint_is_an_error_naming_the_config_key_and_the_path() {
    let device = dgstereo_core::default_device();
    let missing = PriorConfig::DepthAnythingV2 {
        weights: Path::new("/nonexistent/dav2.pth").into(),
        encoder: None,
        input_size: 518,
    };
    let err = missing.init(&device).unwrap_err().to_string();
    assert!(err.contains("prior.weights") && err.contains("/nonexistent/dav2.pth"), "{err}");
    // Wrapped in a cache it fails the same way instead of falling back.
    let cached =
        PriorConfig::Cache { dir: std::env::temp_dir().join("dgstereo-prior-unused"), inner: Box::new(missing) };
    let err = cached.init(&device).unwrap_err().to_string();
    assert!(err.contains("/nonexistent/dav2.pth"), "{err}");
    // An input size below one patch is rejected by key as well.
    let tiny = PriorConfig::DepthAnythingV2 { weights: "/nonexistent/dav2.pth".into(), encoder: None, input_size: 7 };
    assert!(tiny.init(&device).unwrap_err().to_string().contains("prior.input_size"));
}

fn write_reference(path: &Path, input_shape: Vec<usize>) {
    let array = |shape: Vec<usize>| FloatArray { values: vec![0.5; shape.iter().product()], shape };
    let tensors = BTreeMap::from([
        ("input.image".to_string(), array(input_shape)),
        ("output.depth".to_string(), array(vec![1, 28, 28])),
    ]);
    write_float_tensors(path, &tensors, None).unwrap();
}

#[test]
fn a_malformed_reference_is_an_error_naming_the_file_and_the_key() {
    let dir = std::env::temp_dir().join(format!("dgstereo-prior-reference-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let device = dgstereo_core::default_device();
    let weights = PathBuf::from("/nonexistent/dav2.pth");
    // Sides that are not multiples of 14 would make the patch embedding drop pixels.
    let reference = dir.join("bad_size.safetensors");
    write_reference(&reference, vec![1, 3, 20, 28]);
    let err = verify_depth_anything_v2(&weights, &reference, &device).unwrap_err().to_string();
    assert!(err.contains("bad_size.safetensors") && err.contains("input.image"), "{err}");
    // A file that is not safetensors at all.
    let garbage = dir.join("garbage.safetensors");
    std::fs::write(&garbage, b"not a tensor file").unwrap();
    let err = verify_depth_anything_v2(&weights, &garbage, &device).unwrap_err().to_string();
    assert!(err.contains("garbage.safetensors"), "{err}");
    // A good reference with a missing checkpoint names the checkpoint.
    let good = dir.join("good.safetensors");
    write_reference(&good, vec![1, 3, 28, 28]);
    let err = verify_depth_anything_v2(&weights, &good, &device).unwrap_err().to_string();
    assert!(err.contains("/nonexistent/dav2.pth"), "{err}");
    std::fs::remove_dir_all(&dir).ok();
}
