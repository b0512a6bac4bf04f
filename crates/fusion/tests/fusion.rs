//! Behaviour of the fusion modules: config, depth normalisation, initialisation, gradients and
//! the deformable conv's offset convention.

use burn::module::{Module, ModuleVisitor, Param};
use burn::nn::conv::Conv2dConfig;
use burn::tensor::{Device, Distribution, Gradients, Tensor};
use dgstereo_core::tensor::{max_abs_diff, to_vec};
use dgstereo_core::{Error, default_device};
use dgstereo_fusion::{ConvFusion, DeformableFusion, Fusion, FusionConfig, FusionTarget, ImageFusion, normalize_depth};
use proptest::prelude::*;

const SIZE: [usize; 4] = [2, 3, 10, 14];

fn image(device: &Device) -> Tensor<4> {
    Tensor::random(SIZE, Distribution::Uniform(0.0, 255.0), device)
}

fn depth(device: &Device) -> Tensor<4> {
    Tensor::random([SIZE[0], 1, SIZE[2], SIZE[3]], Distribution::Uniform(0.3, 40.0), device)
}

fn learned(device: &Device) -> Vec<(&'static str, Fusion)> {
    vec![
        ("deformable", FusionConfig::deformable().init(device).unwrap()),
        ("conv", FusionConfig::conv().init(device).unwrap()),
    ]
}

#[test]
fn configs_read_from_toml() {
    let read = |text: &str| toml::from_str::<FusionConfig>(text);
    assert_eq!(read("kind = \"none\"").unwrap(), FusionConfig::None {});
    // `none` takes no keys either: a key meant for another kind is an error naming it.
    let e = read("kind = \"none\"\nfeatures = 4").unwrap_err().to_string();
    assert!(e.contains("features"), "{e}");
    let config = read("kind = \"deformable\"").unwrap();
    assert_eq!(config, FusionConfig::deformable());
    assert_eq!(config.target(), FusionTarget::Both);
    assert!(config.needs_prior());
    let config = read("kind = \"conv\"\ntarget = \"context-only\"\nfeatures = 4").unwrap();
    assert_eq!(config, FusionConfig::Conv { target: FusionTarget::ContextOnly, features: 4 });
    assert_eq!(config.target(), FusionTarget::ContextOnly);
    assert!(!FusionConfig::None {}.needs_prior());
    assert!(read("kind = \"deformable\"\ntau = 1").is_err());
    assert!(read("kind = \"deformable\"\ntarget = \"feature\"").is_err());
    let thin = FusionConfig::Deformable { target: FusionTarget::Both, features: 2 };
    let problems = thin.problems();
    assert_eq!(problems.len(), 1);
    assert_eq!(problems[0].key, "features");
    assert!(thin.validate().is_err());
    let text = toml::to_string(&FusionConfig::deformable()).unwrap();
    assert_eq!(read(&text).unwrap(), FusionConfig::deformable());
}

#[test]
fn none_is_the_identity() {
    let device = default_device();
    let x = image(&device);
    let out = FusionConfig::None {}.init(&device).unwrap().fuse(x.clone(), None).unwrap();
    assert_eq!(max_abs_diff(out, x), 0.0);
}

#[test]
fn learned_fusions_start_close_to_the_identity() {
    let device = default_device();
    let x = image(&device);
    for (name, fusion) in learned(&device) {
        let out = fusion.fuse(x.clone(), Some(depth(&device))).unwrap();
        assert_eq!(out.dims(), SIZE, "{name}");
        let values = to_vec(out.clone());
        assert!(values.iter().all(|v| v.is_finite()), "{name}");
        let diff = to_vec((out - x.clone()).abs());
        let mean = diff.iter().sum::<f32>() / diff.len() as f32;
        let max = diff.iter().copied().fold(0.0, f32::max);
        assert!(mean < 0.02 * 255.0 && max < 0.1 * 255.0, "{name}: mean {mean}, max {max}");
    }
}

#[test]
fn prior_at_another_resolution_is_resized() {
    let device = default_device();
    let small = Tensor::random([SIZE[0], 1, 5, 7], Distribution::Uniform(0.0, 1.0), &device);
    for (name, fusion) in learned(&device) {
        let out = fusion.fuse(image(&device), Some(small.clone())).unwrap();
        assert_eq!(out.dims(), SIZE, "{name}");
    }
}

/// A learned fusion without its prior is an error naming `fusion.kind`, not a panic.
#[test]
fn learned_fusion_without_prior_is_an_error() {
    let device = default_device();
    for (name, fusion) in learned(&device) {
        match fusion.fuse(image(&device), None) {
            Err(Error::Config(problem)) => {
                assert_eq!(problem.key, "fusion.kind", "{name}");
                assert!(problem.reason.contains(name), "{name}: {problem}");
            }
            other => panic!("{name}: expected a configuration error, got {other:?}"),
        }
    }
}

/// An invalid configuration is refused by `init` with the key, not a panic.
#[test]
fn init_refuses_an_invalid_config() {
    let device = default_device();
    for kind in FusionConfig::variants() {
        let thin = kind.with_parameters(FusionTarget::Both, 2);
        match thin.init(&device) {
            Ok(_) => assert!(thin.validate().is_ok(), "{thin:?} builds but does not validate"),
            Err(Error::Config(problem)) => assert_eq!(problem.key, "features", "{thin:?}"),
            Err(other) => panic!("{thin:?}: {other}"),
        }
    }
    assert!(DeformableFusion::new(2, &device).is_err());
    assert!(ConvFusion::new(2, &device).is_err());
}

/// `FusionConfig::variants` lists every kind, once, in the enum's order, and names each as TOML
/// does: the tests and checks that draw their kinds from it see every kind.
#[test]
fn every_kind_is_listed() {
    let listed: Vec<String> = FusionConfig::variants().iter().map(|v| v.kind().to_string()).collect();
    assert_eq!(listed, dgstereo_core::serde_names::accepted_kinds::<FusionConfig>("kind").unwrap());
    for variant in FusionConfig::variants() {
        let text = toml::to_string(&variant).unwrap();
        assert!(text.contains(&format!("kind = \"{}\"", variant.kind())), "{text}");
        assert_eq!(toml::from_str::<FusionConfig>(&text).unwrap(), variant);
        assert!(variant.validate().is_ok(), "{variant:?}");
    }
}

/// Every kind refuses a key it does not have, naming it: `none`, which has no keys, as well as
/// the learned kinds.
#[test]
fn every_kind_refuses_unknown_keys() {
    for config in FusionConfig::variants() {
        let text = format!("featurez = 8\n{}", toml::to_string(&config).unwrap());
        let message = toml::from_str::<FusionConfig>(&text).expect_err(&text).to_string();
        assert!(message.contains("featurez"), "{}: {message}", config.kind());
    }
}

/// Checks that every float parameter has a finite, non-zero gradient.
struct GradientCheck<'a> {
    grads: &'a Gradients,
    checked: usize,
}

impl ModuleVisitor for GradientCheck<'_> {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        let grad = param.val().grad(self.grads).expect("every parameter gets a gradient");
        let values = to_vec(grad);
        assert!(values.iter().all(|g| g.is_finite()), "non-finite gradient");
        assert!(values.iter().any(|g| *g != 0.0), "all-zero gradient of shape {:?}", param.dims());
        self.checked += 1;
    }
}

#[test]
fn every_parameter_gets_a_finite_gradient() {
    let device = default_device().autodiff();
    for ((name, fusion), params) in learned(&device).into_iter().zip([8, 6]) {
        let x = image(&device);
        let goal = image(&device);
        let out = fusion.fuse(x, Some(depth(&device))).unwrap();
        let loss = (out - goal).powi_scalar(2).mean();
        let grads = loss.backward();
        let mut check = GradientCheck { grads: &grads, checked: 0 };
        fusion.visit(&mut check);
        assert_eq!(check.checked, params, "{name}");
    }
}

/// A conv fusion with the deformable fusion's weights (its mixer weights made random first, so
/// that the comparison exercises every tap).
fn matched_pair(device: &Device) -> (DeformableFusion, ConvFusion) {
    let mut deformable = DeformableFusion::new(8, device).unwrap();
    let weight = Tensor::random(deformable.mixer.weight.dims(), Distribution::Uniform(-0.2, 0.2), device);
    let bias = Tensor::random([3], Distribution::Uniform(-1.0, 1.0), device);
    deformable.mixer.weight = Param::from_tensor(weight.clone());
    deformable.mixer.bias = Some(Param::from_tensor(bias.clone()));
    let mut mixer =
        Conv2dConfig::new([16, 3], [3, 3]).with_padding(burn::nn::PaddingConfig2d::Explicit(1, 1, 1, 1)).init(device);
    mixer.weight = Param::from_tensor(weight);
    mixer.bias = Some(Param::from_tensor(bias));
    let conv = ConvFusion { projection: deformable.projection.clone(), mixer };
    (deformable, conv)
}

#[test]
fn deformable_with_zero_offsets_equals_the_conv_variant() {
    let device = default_device();
    let (deformable, conv) = matched_pair(&device);
    let (x, d) = (image(&device), depth(&device));
    let a = deformable.forward(x.clone(), d.clone());
    let b = conv.forward(x, d);
    let scale = to_vec(b.clone().abs()).into_iter().fold(0.0, f32::max);
    let diff = max_abs_diff(a, b);
    assert!(diff <= 1e-4 * scale.max(1.0), "{diff} (scale {scale})");
}

#[test]
fn integer_offsets_shift_the_sampling_grid() {
    let device = default_device();
    let [n, _, h, w] = SIZE;
    for (dy, dx) in [(0i32, 1i32), (1, 0), (-1, 0), (0, -1)] {
        let (mut deformable, conv) = matched_pair(&device);
        // Constant offsets through the bias; torchvision order: (dy, dx) per tap.
        let bias: Vec<f32> = (0..18).map(|c| if c % 2 == 0 { dy as f32 } else { dx as f32 }).collect();
        deformable.offset.bias = Some(Param::from_tensor(Tensor::from_floats(bias.as_slice(), &device)));
        let (x, d) = (image(&device), depth(&device));
        let shifted = deformable.forward(x.clone(), d.clone());
        let plain = conv.forward(x, d);
        // shifted(y, x) = plain(y + dy, x + dx) wherever the right-hand side is inside the image.
        let rows = (0.max(-dy) as usize)..((h as i32 - dy.max(0)) as usize);
        let cols = (0.max(-dx) as usize)..((w as i32 - dx.max(0)) as usize);
        let src_rows = ((rows.start as i32 + dy) as usize)..((rows.end as i32 + dy) as usize);
        let src_cols = ((cols.start as i32 + dx) as usize)..((cols.end as i32 + dx) as usize);
        let a = shifted.slice([0..n, 0..3, rows, cols]);
        let b = plain.slice([0..n, 0..3, src_rows, src_cols]);
        let scale = to_vec(b.clone().abs()).into_iter().fold(0.0, f32::max);
        let diff = max_abs_diff(a, b);
        assert!(diff <= 1e-4 * scale.max(1.0), "({dy}, {dx}): {diff}");
    }
}

#[test]
fn constant_depth_normalises_to_zero() {
    let device = default_device();
    let d = Tensor::<4>::ones([2, 1, 4, 5], &device).mul_scalar(3.7);
    let out = normalize_depth(d, [4, 5]);
    assert!(to_vec(out).iter().all(|v| *v == 0.0));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(16))]

    /// Each image is mapped to [0, 255] with both ends reached, independently of the others, and
    /// any positive affine change of the prior's scale leaves it unchanged.
    #[test]
    fn depth_normalisation_is_per_image_and_scale_free(
        values in proptest::collection::vec(0.0f32..100.0, 2 * 3 * 4),
        scale in 0.01f32..100.0,
        shift in -50.0f32..50.0,
    ) {
        prop_assume!(values[..12].iter().copied().fold(f32::MIN, f32::max)
            - values[..12].iter().copied().fold(f32::MAX, f32::min) > 1e-2);
        prop_assume!(values[12..].iter().copied().fold(f32::MIN, f32::max)
            - values[12..].iter().copied().fold(f32::MAX, f32::min) > 1e-2);
        let device = default_device();
        let d = dgstereo_core::tensor::from_vec(values, [2, 1, 3, 4], &device);
        let out = normalize_depth(d.clone(), [3, 4]);
        for image in to_vec(out.clone()).chunks(12) {
            let min = image.iter().copied().fold(f32::MAX, f32::min);
            let max = image.iter().copied().fold(f32::MIN, f32::max);
            prop_assert!(min.abs() < 1e-3 && (max - 255.0).abs() < 1e-2, "{} {}", min, max);
        }
        let affine = normalize_depth(d.mul_scalar(scale).add_scalar(shift), [3, 4]);
        prop_assert!(max_abs_diff(out, affine) < 0.1);
    }
}

#[test]
fn a_module_built_on_a_plain_device_trains_after_fork_and_train() {
    // burn 0.22: a module forked to an autodiff device needs `.train()` to track gradients.
    let device = default_device();
    let fusion = FusionConfig::deformable().init(&device).unwrap().fork(&device.clone().autodiff()).train();
    let autodiff = device.autodiff();
    let out = fusion.fuse(image(&autodiff), Some(depth(&autodiff))).unwrap();
    let grads = out.mean().backward();
    let Fusion::Deformable(inner) = &fusion else { unreachable!() };
    assert!(inner.offset.weight.val().grad(&grads).is_some());
    assert!(inner.projection.image.weight.val().grad(&grads).is_some());
}
