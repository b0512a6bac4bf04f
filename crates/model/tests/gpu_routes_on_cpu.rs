//! GPU inference's composition, computed on the CPU: the forward pass with the GPU routes
//! (the kernels' GPU formulations: the gathered im2col and its strided and few-output forms,
//! burn's `interpolate`, the gathered lookup) equals the pass with burn's stock operations, and
//! so does the pass with the host kernels.
//!
//! Each route is tested against its stock operation in the kernels crate; this checks that they
//! compose into the same network, end to end, where a GPU is not at hand (CI). Each pass runs
//! with its path pinned on the calling thread (`dgstereo_kernels::with_path`).

use std::path::Path;

use burn::tensor::{Device, Distribution, Tensor};
use dgstereo_core::DepthPrior;
use dgstereo_core::tensor::{from_vec, max_abs_diff};
use dgstereo_kernels::{Op, Path as KernelPath, path, with_path};
use dgstereo_model::{ModelConfig, StereoModel, checkpoint};

/// A textured pair whose right view is the left shifted by 5 pixels.
fn pair(h: usize, w: usize, device: &Device) -> (Tensor<4>, Tensor<4>) {
    let value = |c: usize, y: usize, x: f32| {
        let (x, y) = (x + 31.0 * c as f32, y as f32);
        127.0 + 60.0 * (0.37 * x + 0.11 * y).sin() + 50.0 * (0.13 * x - 0.29 * y).cos() + 10.0 * (1.7 * x).sin()
    };
    let image = |dx: f32| {
        let v = (0..3).flat_map(|c| (0..h).flat_map(move |y| (0..w).map(move |x| value(c, y, x as f32 + dx))));
        from_vec(v.collect(), [1, 3, h, w], device)
    };
    (image(0.0), image(5.0))
}

/// The bundled trained model and the paper's model (DGIA and Gradient-GRU, random weights, a
/// random prior), each with its inputs.
fn models(device: &Device) -> Vec<(&'static str, StereoModel, [Tensor<4>; 2], Option<DepthPrior>)> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/weights/raft-stereo-default.safetensors");
    let json = checkpoint::safetensors_metadata(&path, "model_config").unwrap().expect("config in the metadata");
    let config = ModelConfig::from_checkpoint_json(&json).unwrap();
    let network = checkpoint::load_safetensors(config.init(device).unwrap(), &path).unwrap();
    let bundled = StereoModel::new(network, config, device.clone());
    let paper: ModelConfig = serde_json::from_str(
        r#"{"fusion": {"kind": "deformable", "target": "both", "features": 8}, "updater": {"guidance": "gradient"}}"#,
    )
    .unwrap();
    let paper = StereoModel::new(paper.init(device).unwrap(), paper, device.clone());
    let prior = |h, w| Tensor::random([1, 1, h, w], Distribution::Uniform(0.1, 1.0), device);
    let (l, r) = pair(64, 128, device);
    let (pl, pr) = pair(64, 96, device);
    let paper_prior = DepthPrior { left: prior(64, 96), right: prior(64, 96) };
    vec![("bundled", bundled, [l, r], None), ("paper", paper, [pl, pr], Some(paper_prior))]
}

#[test]
fn the_gpu_routes_compute_the_stock_network() {
    let device = Device::flex();
    let models = models(&device);
    let run = |(_, model, [l, r], prior): &(&str, StereoModel, [Tensor<4>; 2], Option<DepthPrior>)| {
        model.predict(l.clone(), r.clone(), prior.as_ref(), 4, false, None).unwrap().last()
    };
    assert_eq!(path(&device, Op::Conv), KernelPath::Host, "the routes are off on the CPU by default");
    let stock: Vec<Tensor<4>> = with_path(KernelPath::Stock, || models.iter().map(run).collect());
    for pinned in [KernelPath::Gpu, KernelPath::Host] {
        with_path(pinned, || assert_eq!(path(&device, Op::Conv), pinned));
        for (m, stock) in models.iter().zip(&stock) {
            let routed = with_path(pinned, || run(m));
            let scale = stock.clone().abs().max().into_scalar::<f32>().max(1.0);
            let diff = max_abs_diff(routed, stock.clone()) / scale;
            assert!(diff < 1e-4, "{} on {pinned:?}: the pass differs by {diff} of the disparity's scale", m.0);
        }
    }
}
