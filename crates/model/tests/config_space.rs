//! Every configuration that `ModelConfig::validate` accepts builds and runs; every other one is
//! refused with a message naming its key.
//!
//! Random points of the configuration space (n_downsample, context norm, correlation levels and
//! radius, equal and unequal hidden widths, GRU levels, shared backbone, slow-fast schedule,
//! fusion and guidance kinds, correlation implementation, trunk widths, motion kind, update
//! clip, scale lookup and update, the encoders' depth features and the initialiser without a
//! monocular network) at small widths and sizes; DEFOM-Stereo's monocular network beside it, in
//! a few small configurations. A configuration either fails
//! validation with an error naming a key, or builds, runs an inference pass (finite disparity
//! of the input's size after padding by `pad_divisor`) and a training-mode pass on the autodiff
//! device whose backward gives finite gradients. Beside it: unequal hidden widths at the
//! reference's sizes, and the checkpoint keys of both encoder layouts.

use burn::module::{Module, ModuleVisitor, Param};
use burn::tensor::{Device, Gradients, Tensor};
use dgstereo_core::tensor::{from_vec, to_vec};
use dgstereo_core::{DepthPrior, default_device};
use dgstereo_model::costvolume::{CorrelationImplementation, ScaleLookup};
use dgstereo_model::encoder::{DepthFeatureInput, EncoderLayout, NormKind};
use dgstereo_model::fusion::{FusionConfig, FusionTarget};
use dgstereo_model::prior::{DepthAnythingV2Encoder, MonocularConfig};
use dgstereo_model::updater::{GuidanceKind, MotionKind, ScaleUpdateConfig};
use dgstereo_model::{InitialDisparity, ModelConfig, StereoModel};
use proptest::prelude::*;

fn norm() -> impl Strategy<Value = NormKind> {
    prop_oneof![Just(NormKind::Batch), Just(NormKind::Group), Just(NormKind::Instance), Just(NormKind::None)]
}

/// Every fusion kind the fusion crate lists, with random parameters (some invalid).
fn fusion() -> impl Strategy<Value = FusionConfig> {
    let target = prop_oneof![Just(FusionTarget::Both), Just(FusionTarget::ContextOnly)];
    (prop::sample::select(FusionConfig::variants()), target, 1usize..=8)
        .prop_map(|(kind, target, features)| kind.with_parameters(target, features))
}

/// Every guidance kind the updater crate lists.
fn guidance() -> impl Strategy<Value = GuidanceKind> {
    prop::sample::select(GuidanceKind::ALL.to_vec())
}

fn hidden_dims() -> impl Strategy<Value = [usize; 3]> {
    let width = prop::sample::select(vec![8usize, 16, 24]);
    prop_oneof![width.clone().prop_map(|d| [d; 3]), [width.clone(), width.clone(), width]]
}

/// DEFOM-Stereo's variants without its monocular network (the kinds that need one are refused):
/// the motion kind, the update clip, the scale lookup's radius and the scale iterations (a scale
/// update without a lookup is refused), the encoders' depth features and the initialiser.
type DefomVariants = (MotionKind, bool, Option<usize>, Option<usize>, DepthFeatureInput, InitialDisparity);

fn defom_variants() -> impl Strategy<Value = DefomVariants> {
    (
        prop::sample::select(MotionKind::ALL.to_vec()),
        any::<bool>(),
        prop::option::of(0usize..=2),
        prop::option::of(0usize..=3),
        prop::sample::select(DepthFeatureInput::ALL.to_vec()),
        prop::sample::select(InitialDisparity::variants()),
    )
}

/// Applies [`DefomVariants`] to `c`.
fn with_defom_variants(mut c: ModelConfig, v: DefomVariants) -> ModelConfig {
    let (motion, clip, scale_radius, scale_iters, depth_features, initial) = v;
    c.updater.motion = motion;
    c.updater.delta_clip = clip;
    c.correlation.scale_lookup = scale_radius.map(|radius| ScaleLookup { radius, ..ScaleLookup::default() });
    c.updater.scale_update = scale_iters.map(|iters| ScaleUpdateConfig { iters });
    c.encoder.depth_features = depth_features;
    c.initial_disparity = initial;
    c
}

fn config() -> impl Strategy<Value = ModelConfig> {
    let updater = (2usize..=3, 1usize..=3, hidden_dims(), any::<bool>(), guidance());
    // Trunk widths that a group norm (width / 8 groups) can and cannot split.
    let trunk = prop::sample::select(vec![[16usize, 16, 24], [8, 16, 16], [12, 16, 20], [16, 17, 24], [4, 16, 16]]);
    // RAFT-Stereo's two layouts (the MobileNetV2 pyramid has its own widths and stride).
    let layouts = prop::sample::select(vec![EncoderLayout::Separate, EncoderLayout::SharedBackbone]);
    let encoder = (norm(), layouts, prop::sample::select(vec![16usize, 32]), trunk);
    let implementation = prop_oneof![Just(CorrelationImplementation::Reg), Just(CorrelationImplementation::Alt)];
    let correlation = (0usize..=4, 0usize..=4, implementation);
    (updater, encoder, correlation, fusion(), defom_variants()).prop_map(
        |(
            (n_downsample, n_gru_layers, hidden, slow_fast, guidance),
            (norm, layout, feature_dim, trunk),
            (levels, radius, implementation),
            fusion,
            defom,
        )| {
            let mut c = ModelConfig { fusion, ..Default::default() };
            c.updater.n_downsample = n_downsample;
            c.updater.n_gru_layers = n_gru_layers;
            c.updater.hidden_dims = hidden;
            c.updater.slow_fast_gru = slow_fast;
            c.updater.guidance = guidance;
            c.encoder.context_norm = norm;
            c.encoder.layout = layout;
            c.encoder.feature_dim = feature_dim;
            c.encoder.trunk_dims = trunk;
            c.correlation.levels = levels;
            c.correlation.radius = radius;
            c.correlation.implementation = implementation;
            with_defom_variants(c, defom)
        },
    )
}

/// A textured pair (the right view shifted by 2 pixels) and a ramp prior, `[1, C, h, w]`.
fn inputs(size: [usize; 2], device: &Device) -> (Tensor<4>, Tensor<4>, DepthPrior) {
    let [h, w] = size;
    let view = |shift: f32| {
        let values = (0..3 * h * w)
            .map(|i| {
                let (c, y, x) = (i / (h * w), (i / w) % h, i % w);
                let x = x as f32 + shift;
                127.5 + 100.0 * ((0.37 * x + c as f32).sin() * (0.23 * y as f32 + 0.7).cos())
            })
            .collect();
        from_vec(values, [1, 3, h, w], device)
    };
    let ramp = || from_vec((0..h * w).map(|i| 1.0 + (i % w) as f32 / w as f32).collect(), [1, 1, h, w], device);
    (view(0.0), view(2.0), DepthPrior { left: ramp(), right: ramp() })
}

/// Counts the parameters with a gradient; notes the non-finite ones.
struct GradientCheck<'a> {
    grads: &'a Gradients,
    with_gradient: usize,
    non_finite: usize,
}

impl ModuleVisitor for GradientCheck<'_> {
    fn visit_float<const D: usize>(&mut self, param: &Param<Tensor<D>>) {
        if let Some(grad) = param.val().grad(self.grads) {
            self.with_gradient += 1;
            self.non_finite += to_vec(grad).iter().any(|g| !g.is_finite()) as usize;
        }
    }
}

/// Builds `config`, runs inference and one training-mode forward and backward pass.
fn builds_and_runs(config: &ModelConfig, size: [usize; 2], iters: usize) -> Result<(), String> {
    let device = default_device();
    let prior = |p: DepthPrior| config.needs_prior().then_some(p);
    let network = config.init(&device).map_err(|e| e.to_string())?;
    let (left, right, p) = inputs(size, &device);
    let model = StereoModel::new(network, config.clone(), device.clone());
    let out = model.predict(left, right, prior(p).as_ref(), iters, false, None).map_err(|e| e.to_string())?;
    let disparity = out.disparities.last().ok_or("no disparity")?.clone();
    if disparity.dims() != [1, 1, size[0], size[1]] {
        return Err(format!("disparity is {:?}", disparity.dims()));
    }
    if to_vec(disparity).iter().any(|d| !d.is_finite()) {
        return Err("non-finite disparity".into());
    }

    let ad = device.clone().autodiff();
    let network = config.init(&device).map_err(|e| e.to_string())?.fork(&ad).train();
    let (left, right, p) = inputs(size, &ad);
    let model = StereoModel::new(network, config.clone(), ad.clone());
    let out = model.predict(left, right, prior(p).as_ref(), iters, true, None).map_err(|e| e.to_string())?;
    if out.disparities.len() != iters {
        return Err(format!("{} disparities for {iters} iterations", out.disparities.len()));
    }
    let loss = out.disparities.into_iter().map(|d| d.sub_scalar(2.0).abs().mean()).reduce(|a, b| a + b).unwrap();
    if !to_vec(loss.clone())[0].is_finite() {
        return Err("non-finite loss".into());
    }
    let grads = loss.backward();
    let mut check = GradientCheck { grads: &grads, with_gradient: 0, non_finite: 0 };
    model.network.visit(&mut check);
    if check.with_gradient == 0 || check.non_finite > 0 {
        return Err(format!("{} parameters with a gradient, {} non-finite", check.with_gradient, check.non_finite));
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 12, max_shrink_iters: 32, ..ProptestConfig::default() })]

    #[test]
    fn every_accepted_configuration_builds_and_runs(
        config in config(),
        size in (24usize..=64, 24usize..=64),
        iters in 2usize..=3,
    ) {
        match config.validate() {
            Err(e) => {
                let message = e.to_string();
                let keys = ["updater.", "encoder.", "correlation.", "fusion.", "initial_disparity."];
                prop_assert!(keys.iter().any(|k| message.contains(k)), "{message} names no key");
            }
            Ok(()) => {
                let run = builds_and_runs(&config, [size.0, size.1], iters);
                prop_assert!(run.is_ok(), "{config:?}: {run:?}");
            }
        }
    }
}

/// Every fusion and guidance kind the stage crates list is answered by the one prior check
/// (`ModelConfig::check_prior`): without a prior, a network the check lets through runs, and one
/// it refuses is refused naming the consuming key. A new kind that consumes the prior without
/// saying so fails here (its forward pass errs or panics without one).
#[test]
fn every_kind_is_covered_by_the_prior_check() {
    let device = default_device();
    for fusion in FusionConfig::variants() {
        for guidance in GuidanceKind::ALL {
            let mut config = ModelConfig { fusion: fusion.clone(), ..Default::default() };
            config.updater.guidance = guidance;
            config.updater.hidden_dims = [8; 3];
            config.encoder.feature_dim = 16;
            config.encoder.trunk_dims = [16, 16, 24];
            let label = format!("{} fusion, {} guidance", fusion.kind(), guidance.name());
            assert!(config.check_prior(true).is_ok(), "{label}");
            match config.check_prior(false) {
                Ok(()) => {
                    assert!(!config.needs_prior(), "{label}");
                    let network = config.init(&device).unwrap();
                    let (left, right, _) = inputs([32, 32], &device);
                    let out = network.forward_flow(left, right, None, 1, Default::default());
                    assert!(out.is_ok(), "{label} runs without a prior: {:?}", out.err());
                }
                Err(dgstereo_core::Error::Config(problem)) => {
                    assert!(config.needs_prior(), "{label}");
                    assert!(["fusion.kind", "updater.guidance"].contains(&problem.key.as_str()), "{label}: {problem}");
                }
                Err(other) => panic!("{label}: {other}"),
            }
        }
    }
}

/// DEFOM-Stereo's network at small widths (its monocular network is ViT-S whatever the rest):
/// the whole variant, and the monocular network with only the encoders or only the initialiser
/// reading it, on both cost volumes and both grids, build, run and train.
#[test]
fn defom_configurations_build_and_run() {
    let small = |c: &mut ModelConfig| {
        c.updater.hidden_dims = [8; 3];
        c.encoder.feature_dim = 16;
        c.encoder.trunk_dims = [16, 16, 24];
        c.monocular = MonocularConfig::DepthAnythingV2 { encoder: DepthAnythingV2Encoder::Vits };
    };
    let full = || {
        let mut c = with_defom_variants(
            ModelConfig::default(),
            (
                MotionKind::Disparity,
                true,
                Some(2),
                Some(2),
                DepthFeatureInput::Added,
                InitialDisparity::scaled_inverse_depth(),
            ),
        );
        c.correlation.levels = 2;
        small(&mut c);
        c
    };
    let mut encoders_only = full();
    encoders_only.initial_disparity = InitialDisparity::Zero {};
    encoders_only.correlation.implementation = CorrelationImplementation::Alt;
    encoders_only.updater.n_downsample = 3;
    let mut initialiser_only = full();
    initialiser_only.encoder.depth_features = DepthFeatureInput::None;
    initialiser_only.updater.motion = MotionKind::Flow;
    initialiser_only.updater.n_gru_layers = 2;
    for config in [full(), encoders_only, initialiser_only] {
        config.validate().unwrap_or_else(|e| panic!("{config:?}: {e}"));
        builds_and_runs(&config, [40, 56], 3).unwrap_or_else(|e| panic!("{config:?}: {e}"));
    }
    // A monocular network nothing reads is refused by its key.
    let mut unread = full();
    unread.encoder.depth_features = DepthFeatureInput::None;
    unread.initial_disparity = InitialDisparity::Zero {};
    let e = unread.validate().unwrap_err().to_string();
    assert!(e.contains("monocular.kind"), "{e}");
}

/// The reference's widths with unequal hidden widths (each level's context convolution takes its
/// own level's width).
#[test]
fn unequal_hidden_widths_run() {
    let mut config = ModelConfig::default();
    config.updater.hidden_dims = [64, 96, 128];
    config.validate().expect("unequal hidden widths are valid");
    builds_and_runs(&config, [64, 64], 2).expect("runs");
}

/// Saved checkpoints keep the reference's top-level keys (`fnet.`, `cnet.`, `conv2.`, IGEV-Stereo's
/// `feature.`, `stem_2.`, `stem_4.`) for every encoder layout, load back into the same layout,
/// and are readable by others (0644).
#[test]
fn saved_keys_keep_the_reference_names() {
    let device = default_device();
    for layout in EncoderLayout::ALL {
        let mut config = ModelConfig::default();
        config.encoder.layout = layout;
        config.encoder.trunk_dims = [16, 16, 24];
        let model = config.init(&device).unwrap();
        let path = std::env::temp_dir().join(format!(
            "config-space-keys-{}-{}.safetensors",
            std::process::id(),
            layout.name()
        ));
        dgstereo_model::checkpoint::save_safetensors(&model, &path, &[]).unwrap();
        // Written through a temporary file that is gone, and readable by others as any output.
        assert!(!path.with_extension("safetensors.tmp").exists(), "the temporary file is left behind");
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = std::fs::metadata(&path).unwrap().permissions().mode();
            assert_eq!(mode & 0o644, 0o644, "weights file mode {mode:o}");
        }
        let bytes = std::fs::read(&path).unwrap();
        let file = safetensors::SafeTensors::deserialize(&bytes).unwrap();
        let mut tops: Vec<String> =
            file.names().iter().map(|k| k.split('.').next().unwrap_or_default().to_string()).collect();
        tops.sort();
        tops.dedup();
        let expected: &[&str] = match layout {
            EncoderLayout::Separate => &["cnet", "context_zqr_convs", "fnet", "update_block"],
            EncoderLayout::SharedBackbone => &["cnet", "context_zqr_convs", "conv2", "update_block"],
            EncoderLayout::MobilenetPyramid => {
                &["cnet", "context_zqr_convs", "feature", "stem_2", "stem_4", "update_block"]
            }
        };
        assert_eq!(tops, expected);
        dgstereo_model::checkpoint::load_safetensors(config.init(&device).unwrap(), &path).unwrap();
        std::fs::remove_file(&path).unwrap();
    }
}
