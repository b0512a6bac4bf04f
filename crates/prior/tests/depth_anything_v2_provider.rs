//! The `depth-anything-v2` provider on a randomly initialised ViT-S (the golden checkpoint is
//! checked in `depth_anything_v2_golden.rs`).

use burn::tensor::{Distribution, Tensor};
use dgstereo_core::tensor::{max_abs_diff, to_vec};
use dgstereo_prior::depth_anything::preprocess::{network_input_size, preprocess};
use dgstereo_prior::{DepthAnythingV2, DepthAnythingV2Encoder, DepthAnythingV2Prior, PriorInput, PriorProvider};

#[test]
fn both_views_run_in_one_batch_and_come_back_at_image_size() {
    let device = dgstereo_core::default_device();
    burn::tensor::Device::seed(&device, 9);
    let model = DepthAnythingV2::new(DepthAnythingV2Encoder::Vits, &device);
    let (h, w, input_size) = (20, 31, 28);
    assert_eq!(network_input_size(h, w, input_size), [28, 42]);
    let left = Tensor::<4>::random([2, 3, h, w], Distribution::Uniform(0.0, 255.0), &device);
    let right = Tensor::<4>::random([2, 3, h, w], Distribution::Uniform(0.0, 255.0), &device);

    let prior = DepthAnythingV2Prior::new(model, input_size);
    let input = PriorInput { left: left.clone(), right: right.clone(), gt_disparity: None, names: vec![] };
    let out = prior.provide(&input).unwrap().expect("a prior");
    assert_eq!(out.left.dims(), [2, 1, h, w]);
    assert_eq!(out.right.dims(), [2, 1, h, w]);
    assert!(to_vec(out.left.clone()).iter().all(|v| v.is_finite() && *v >= 0.0));

    // Same as running each view alone: batching must not mix the views.
    let alone = prior.model().infer(right.clone(), input_size);
    assert!(max_abs_diff(alone, out.right.clone()) < 1e-4);
    let first = prior.model().infer(left.narrow(0, 0, 1), input_size);
    assert!(max_abs_diff(first, out.left.narrow(0, 0, 1)) < 1e-4);

    // The network input has the documented size and ImageNet statistics of a grey image.
    let grey = Tensor::<4>::full([1, 3, h, w], 127.5, &device);
    let x = preprocess(grey, input_size);
    assert_eq!(x.dims(), [1, 3, 28, 42]);
    let v = to_vec(x);
    let expected_red = (0.5 - 0.485) / 0.229;
    assert!((v[0] - expected_red).abs() < 1e-5, "{} vs {expected_red}", v[0]);
}
