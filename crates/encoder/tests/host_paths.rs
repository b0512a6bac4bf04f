//! The encoders' CPU-inference path (host convolution, fused norm + ReLU and residual sum) gives
//! the tensor operations' result: the same module run on the autodiff device takes burn's
//! operations only.

use burn::module::{Module, Param};
use burn::tensor::{Device, Distribution, Tensor};
use dgstereo_core::Probe;
use dgstereo_core::tensor::max_abs_diff;
use dgstereo_encoder::norm::Norm;
use dgstereo_encoder::residual::ResidualBlock;
use dgstereo_encoder::{
    ContextEncoder, EncoderInputs, Encoders, FeatureEncoder, NormKind, SharedBackbone, SharedFeatureHead, StereoEncoder,
};

/// Agreement up to float rounding: the largest difference relative to the largest magnitude
/// (the outputs of these randomly initialised encoders reach tens, where 1e-4 is a few ulps).
fn relative_difference(host: Tensor<4>, stock: Tensor<4>) -> f32 {
    let scale = dgstereo_core::tensor::to_vec(stock.clone()).iter().fold(1.0f32, |m, v| m.max(v.abs()));
    max_abs_diff(host, stock) / scale
}

fn image(device: &Device) -> Tensor<4> {
    Tensor::random([2, 3, 32, 48], Distribution::Uniform(-1.0, 1.0), device)
}

/// Gives every frozen batch norm of a block non-trivial statistics and affine parameters.
fn perturb_batch_norm(norm: &mut Norm, device: &Device) {
    if let Norm::Batch(bn) = norm {
        let c = bn.weight.dims()[0];
        let draw = |lo: f64, hi: f64| Tensor::<1>::random([c], Distribution::Uniform(lo, hi), device);
        bn.weight = Param::from_tensor(draw(0.5, 1.5));
        bn.bias = Param::from_tensor(draw(-0.5, 0.5));
        bn.running_mean = Param::from_tensor(draw(-0.3, 0.3)).set_require_grad(false);
        bn.running_var = Param::from_tensor(draw(0.5, 2.0)).set_require_grad(false);
    }
}

fn perturb_block(block: &mut ResidualBlock, device: &Device) {
    perturb_batch_norm(&mut block.norm1, device);
    perturb_batch_norm(&mut block.norm2, device);
    if let Some(norm) = &mut block.norm3 {
        perturb_batch_norm(norm, device);
    }
}

#[test]
fn feature_encoder_host_path_equals_tensor_operations() {
    let device = Device::flex();
    let encoder = FeatureEncoder::new(32, [16, 24, 32], NormKind::Instance, 2, None, &device);
    let x = image(&device);
    let host = encoder.features(x.clone());
    let ad = device.clone().autodiff();
    let stock = encoder.fork(&ad).features(Tensor::from_data(x.into_data(), &ad));
    let stock = Tensor::<4>::from_data(stock.into_data(), &device);
    let diff = relative_difference(host, stock);
    assert!(diff < 1e-5, "feature encoder: host and tensor paths differ by {diff} (relative)");
}

#[test]
fn context_encoder_host_path_equals_tensor_operations() {
    let device = Device::flex();
    let mut encoder = ContextEncoder::new([16, 16, 16], [16, 24, 32], NormKind::Batch, 2, None, &device);
    perturb_batch_norm(&mut encoder.norm1, &device);
    for block in encoder.layer1.iter_mut().chain(&mut encoder.layer2).chain(&mut encoder.layer3) {
        perturb_block(block, &device);
    }
    let x = image(&device);
    let host = encoder.context(x.clone(), 3);
    let ad = device.clone().autodiff();
    let stock = encoder.fork(&ad).context(Tensor::from_data(x.into_data(), &ad), 3);
    for (level, (h, s)) in host.levels.iter().zip(&stock.levels).enumerate() {
        for j in 0..2 {
            let s = Tensor::<4>::from_data(s[j].clone().into_data(), &device);
            let diff = relative_difference(h[j].clone(), s);
            assert!(diff < 1e-5, "context level {level} head {j}: host and tensor paths differ by {diff} (relative)");
        }
    }
}

/// In training, a context encoder with frozen batch norms takes Winograd in its layers
/// (`ContextEncoder::numerics`, taken by `context`): its result differs from the plain products' in
/// rounding only. With instance norms it keeps the plain products, bit for bit.
#[test]
fn context_encoder_training_forward_takes_winograd_only_with_fixed_norms() {
    let ad = Device::flex().autodiff();
    let x = Tensor::<4>::random([1, 3, 96, 128], Distribution::Uniform(-1.0, 1.0), &ad);
    let outputs = |encoder: &ContextEncoder, guarded: bool| {
        let features = if guarded {
            encoder.context(x.clone(), 3)
        } else {
            {
                let plain = dgstereo_kernels::Numerics::Sensitive;
                encoder.heads(encoder.trunk(x.clone(), plain), 3, plain, None)
            }
        };
        features.levels.into_iter().flatten().map(dgstereo_core::tensor::to_vec).collect::<Vec<_>>()
    };
    let batch = ContextEncoder::new([32, 32, 32], [32, 48, 64], NormKind::Batch, 2, None, &ad);
    assert!(batch.norms_are_fixed());
    let (winograd, plain) = (outputs(&batch, true), outputs(&batch, false));
    assert_ne!(winograd, plain, "the context encoder's training forward kept the plain products");
    for (a, b) in winograd.iter().zip(&plain) {
        let scale = b.iter().fold(1.0f32, |m, v| m.max(v.abs()));
        let worst = a.iter().zip(b).map(|(a, b)| (a - b).abs()).fold(0.0, f32::max) / scale;
        assert!(worst < 1e-4, "Winograd and plain products differ by {worst} (relative)");
    }
    let instance = ContextEncoder::new([32, 32, 32], [32, 48, 64], NormKind::Instance, 2, None, &ad);
    assert!(!instance.norms_are_fixed());
    assert_eq!(outputs(&instance, true), outputs(&instance, false), "an instance-norm encoder took Winograd");
}

/// The shared backbone's context heads take Winograd in training as the separate context encoder
/// does (they feed only the GRUs), while its trunk, which also feeds the feature head's instance
/// norm, keeps the plain products: the features are bit-identical to the unguarded path's.
#[test]
fn shared_backbone_takes_winograd_in_its_heads_only() {
    let ad = Device::flex().autodiff();
    let image = || Tensor::<4>::random([1, 3, 96, 128], Distribution::Uniform(0.0, 255.0), &ad);
    let (left, right) = (image(), image());
    let cnet = ContextEncoder::new([32, 32, 32], [32, 48, 64], NormKind::Batch, 2, None, &ad);
    let encoders = Encoders::Shared(SharedBackbone { cnet, conv2: SharedFeatureHead::new(64, 64, &ad) });
    let inputs = EncoderInputs {
        context_left: left.clone(),
        features_left: left.clone(),
        features_right: right.clone(),
        depth: None,
    };
    let encoded = encoders.encode(inputs, 3, &mut Probe::none()).unwrap();

    let Encoders::Shared(SharedBackbone { cnet, conv2 }) = &encoders else { unreachable!() };
    let normalise = |x: Tensor<4>| x.div_scalar(255.0).mul_scalar(2.0).sub_scalar(1.0);
    let trunk = cnet.trunk(normalise(Tensor::cat(vec![left, right], 0)), dgstereo_kernels::Numerics::Sensitive);
    let plain = cnet.heads(trunk.clone().narrow(0, 0, 1), 3, dgstereo_kernels::Numerics::Sensitive, None);
    let feats = conv2.forward(trunk);
    let to_vec = dgstereo_core::tensor::to_vec;
    assert_eq!(to_vec(encoded.fmap1), to_vec(feats.clone().narrow(0, 0, 1)), "the trunk or feature head changed path");
    assert_eq!(to_vec(encoded.fmap2), to_vec(feats.narrow(0, 1, 1)), "the trunk or feature head changed path");
    let heads = |c: dgstereo_encoder::ContextFeatures| c.levels.into_iter().flatten().map(to_vec).collect::<Vec<_>>();
    let (winograd, plain) = (heads(encoded.context), heads(plain));
    assert_ne!(winograd, plain, "the shared backbone's context heads kept the plain products");
    for (a, b) in winograd.iter().zip(&plain) {
        let scale = b.iter().fold(1.0f32, |m, v| m.max(v.abs()));
        let worst = a.iter().zip(b).map(|(a, b)| (a - b).abs()).fold(0.0, f32::max) / scale;
        assert!(worst < 1e-4, "Winograd and plain products differ by {worst} (relative)");
    }
}
