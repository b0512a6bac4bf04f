//! IGEV-Stereo trained with its official recipe (`experiments/zoo/igev-train.toml`): the file
//! holds `train_stereo.py`'s defaults, timm's ImageNet MobileNetV2 weights load into the feature
//! trunk (`train.feature_init`; the tests write a small file in timm's layout), the loss reads
//! the upsampled initial disparity, which alone trains the volume's classifier and the initial
//! superpixel heads, and a smoke-size run checkpoints and resumes bit-exactly.

mod common;
#[path = "../../../tests/support/official_pth.rs"]
mod official_pth;

use std::path::Path;

use burn::store::ModuleSnapshot;
use dgstereo_core::default_device;
use dgstereo_encoder::Encoders;
use dgstereo_experiment::{ExperimentConfig, load};
use dgstereo_loss::{InitialDisparityTerm, LossConfig};
use dgstereo_model::seeded::{StateDict, StateTensor};
use dgstereo_train::batch::{TrainingData, to_tensors};
use dgstereo_train::feature_init::load_feature_init;
use dgstereo_train::trainer::init_model;
use dgstereo_train::{TrainParts, Trainer};

fn recipe() -> ExperimentConfig {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../experiments/zoo/igev-train.toml");
    let mut runs = load(&path).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(runs.len(), 1);
    runs.remove(0).config
}

/// The timm key of a trunk path, written out from IGEV-Stereo's `Feature` (`layers = [1, 2, 3,
/// 5, 6]`: `block{g}` is `blocks[layers[g - 1]..layers[g]]`); `None` for the decoder.
fn timm_name(path: &str) -> Option<String> {
    const FIRST_STAGE: [usize; 5] = [0, 1, 2, 3, 5];
    if path.starts_with("conv_stem.") || path.starts_with("bn1.") {
        return Some(path.to_string());
    }
    let (group, rest) = path.strip_prefix("block")?.split_once('.')?;
    let (index, rest) = rest.split_once('.')?;
    Some(format!("blocks.{}.{rest}", FIRST_STAGE[group.parse::<usize>().ok()?] + index.parse::<usize>().ok()?))
}

/// Values a function of the key and the position alone (no generator another test could move):
/// within 0.1 of 0, the running variances within 0.5 of 1.
fn values(key: &str, count: usize) -> Vec<f32> {
    let salt = key.bytes().fold(17u64, |h, b| h.wrapping_mul(31).wrapping_add(u64::from(b)));
    let (scale, offset) = if key.ends_with("running_var") { (0.5, 1.0) } else { (0.1, 0.0) };
    (0..count as u64)
        .map(|i| offset + scale * ((salt.wrapping_add(i).wrapping_mul(2_654_435_761) % 2001) as f32 / 1000.0 - 1.0))
        .collect()
}

/// The tensors of a timm `mobilenetv2_100` state dict: the trunk's tensors with the shapes the
/// network has (`edit` may change or drop them) under timm's keys, and what the network does
/// not hold (stage 6, the head, the classifier).
fn timm_state(edit: impl Fn(&str, Vec<usize>) -> Option<Vec<usize>>) -> StateDict {
    // Built under the trainer's initialisation lock: drawing the weights here must not move the
    // generator another test is seeding.
    let model = init_model(&recipe().model, &default_device(), Some(0)).unwrap();
    let Encoders::Pyramid(encoders) = &model.encoder else { panic!("IGEV-Stereo has the pyramid encoders") };
    let mut state: StateDict = encoders
        .feature
        .collect(None, None, true)
        .into_iter()
        .filter_map(|t| {
            let key = timm_name(&t.name)?;
            let shape = edit(&key, t.shape.to_vec())?;
            let values = values(&key, shape.iter().product());
            Some(StateTensor { key, shape, values })
        })
        .collect();
    for (key, shape) in [
        ("blocks.6.0.conv_pw.weight", vec![960, 160, 1, 1]),
        ("conv_head.weight", vec![1280, 320, 1, 1]),
        ("bn2.weight", vec![1280]),
        ("classifier.weight", vec![1000, 1280]),
        ("classifier.bias", vec![1000]),
    ] {
        let values = values(key, shape.iter().product());
        state.push(StateTensor { key: key.into(), shape, values });
    }
    state
}

/// Writes `state` as a safetensors file (float32), with a `num_batches_tracked` (int64) as timm's
/// batch norms hold.
fn write_safetensors(path: &Path, state: &StateDict) {
    let bytes: Vec<(String, Vec<usize>, Vec<u8>)> = state
        .iter()
        .map(|t| (t.key.clone(), t.shape.clone(), t.values.iter().flat_map(|x| x.to_le_bytes()).collect()))
        .collect();
    let tracked = 10i64.to_le_bytes().to_vec();
    let mut views: Vec<(String, safetensors::tensor::TensorView<'_>)> = bytes
        .iter()
        .map(|(k, s, b)| {
            (k.clone(), safetensors::tensor::TensorView::new(safetensors::Dtype::F32, s.clone(), b).unwrap())
        })
        .collect();
    views.push((
        "bn1.num_batches_tracked".into(),
        safetensors::tensor::TensorView::new(safetensors::Dtype::I64, vec![], &tracked).unwrap(),
    ));
    safetensors::serialize_to_file(views, &None, path).unwrap();
}

/// The recipe at smoke size: the official architecture, `iters` iterations, one 32x64
/// synthetic pair a step, the trunk's weights from `feature_init`.
fn smoke_parts(feature_init: Option<&Path>, steps: usize, iters: usize) -> TrainParts {
    let mut config = recipe();
    let tiny = common::tiny_parts(steps, iters, 1e-3, Some(2), 1);
    config.train =
        dgstereo_experiment::TrainingConfig { feature_init: feature_init.map(Path::to_path_buf), ..tiny.train };
    config.data = tiny.data;
    TrainParts::from(config)
}

fn values_of(weights: &[(String, Vec<f32>)], path: &str) -> Vec<f32> {
    weights.iter().find(|(n, _)| n == path).unwrap_or_else(|| panic!("no parameter {path}")).1.clone()
}

#[test]
fn the_recipe_file_holds_the_official_defaults() {
    let config = recipe();
    config.validate().unwrap();
    let t = &config.train;
    assert_eq!((t.steps, t.batch_size, t.crop, t.iters), (200_000, 8, [320, 736], 22));
    assert_eq!((t.lr, t.weight_decay, t.eps, t.clip), (2e-4, 1e-5, 1e-8, 1.0));
    assert_eq!((t.warmup_fraction, t.schedule_extra_steps, t.seed), (0.01, 100, 666));
    assert_eq!(t.validate_every, 10_000);
    assert!(t.feature_init.as_ref().is_some_and(|p| p.ends_with("mobilenetv2_100_ra-b33bc2c4.pth")), "{t:?}");
    assert_eq!(config.loss, LossConfig::igev_stereo());
    assert!(config.model.outputs_initial_disparity() && config.model.has_mobilenet_features());
    assert_eq!((config.data.spatial_scale, config.data.saturation_range), ([-0.2, 0.4], [0.0, 1.4]));
    assert_eq!(config.data.sources.len(), 3);
    let zoo = load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../../experiments/zoo/igev.toml")).unwrap();
    assert_eq!(config.model, zoo[0].config.model, "the architecture is igev.toml's");
}

/// The initial-disparity term and the ImageNet trunk need IGEV-Stereo's network: on RAFT-Stereo
/// or DEFOM-Stereo (whose scaled start the official DEFOM loss does not supervise) the
/// experiment is refused, naming the key.
#[test]
fn the_recipe_keys_need_igev_stereos_network() {
    let defom = load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../../experiments/zoo/defom-vits-train.toml"))
        .unwrap()
        .remove(0)
        .config;
    let raft = ExperimentConfig { model: dgstereo_model::ModelConfig::default(), ..recipe() };
    recipe().validate().unwrap();
    for config in [defom.model, raft.model] {
        let config = ExperimentConfig { model: config, ..recipe() };
        let problems = config.problems();
        let reason = |key: &str| problems.iter().find(|p| p.key == key).map(|p| p.reason.clone());
        let initial = reason("loss.initial_disparity").expect("the loss term is refused");
        assert!(initial.contains("soft-argmin") && initial.contains("superpixel"), "{initial}");
        let trunk = reason("train.feature_init").expect("the ImageNet trunk is refused");
        assert!(trunk.contains("mobilenet-pyramid"), "{trunk}");
    }
}

#[test]
fn feature_init_loads_the_timm_trunk_and_keeps_the_decoder() {
    let device = default_device();
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("mobilenetv2_100.safetensors");
    let state = timm_state(|_, shape| Some(shape));
    write_safetensors(&file, &state);
    let config = recipe().model;
    let fresh = init_model(&config, &device, Some(5)).unwrap();
    let before = common::weights(&fresh);
    let (model, notice) = load_feature_init(fresh, &file).unwrap();
    let after = common::weights(&model);
    // block3 holds timm's stages 3 and 4, block4 stage 5; the running statistics load too.
    for (ours, timm) in [
        ("encoder.feature.conv_stem.weight", "conv_stem.weight"),
        ("encoder.feature.bn1.running_var", "bn1.running_var"),
        ("encoder.feature.block0.0.0.conv_dw.weight", "blocks.0.0.conv_dw.weight"),
        ("encoder.feature.block3.0.3.conv_pwl.weight", "blocks.3.3.conv_pwl.weight"),
        ("encoder.feature.block3.1.0.conv_pw.weight", "blocks.4.0.conv_pw.weight"),
        ("encoder.feature.block4.0.2.bn3.bias", "blocks.5.2.bn3.bias"),
    ] {
        let file_values = &state.iter().find(|t| t.key == timm).unwrap().values;
        assert_eq!(&values_of(&after, ours), file_values, "{ours} is not the file's {timm}");
        assert_ne!(&values_of(&before, ours), file_values, "{ours} held the file's values before");
    }
    // The decoder, the stems and the rest of the network keep their initialisation.
    for kept in
        ["encoder.feature.deconv32_16.", "encoder.feature.conv4.", "encoder.stem_2.", "geometry.", "update_block."]
    {
        assert!(common::identical_under(&before, &after, kept), "{kept} changed");
    }
    assert!(notice.contains("train.feature_init") && notice.contains("6 key(s) of the file ignored"), "{notice}");
}

#[test]
fn a_file_that_does_not_fit_is_refused_by_key() {
    let device = default_device();
    let dir = tempfile::tempdir().unwrap();
    let igev = recipe().model;
    let message = |config: &dgstereo_model::ModelConfig, file: &Path| {
        let model = init_model(config, &device, Some(1)).unwrap();
        load_feature_init(model, file).expect_err("the file does not fit").to_string()
    };
    // Another width at one stage (a mobilenetv2_140 has such shapes).
    let wide = dir.path().join("wide.safetensors");
    write_safetensors(
        &wide,
        &timm_state(|key, shape| {
            Some(if key == "blocks.5.0.conv_pw.weight" { vec![shape[0] + 8, shape[1], 1, 1] } else { shape })
        }),
    );
    let m = message(&igev, &wide);
    assert!(m.contains("train.feature_init") && m.contains("wide.safetensors"), "{m}");
    assert!(m.contains("'blocks.5.0.conv_pw.weight' has shape [584, 96, 1, 1]"), "{m}");
    // A stage missing.
    let short = dir.path().join("short.safetensors");
    write_safetensors(&short, &timm_state(|key, shape| (!key.starts_with("blocks.3.")).then_some(shape)));
    let m = message(&igev, &short);
    assert!(m.contains("missing key 'blocks.3.0.") && m.contains("not a timm mobilenetv2_100 state dict"), "{m}");
    // No file; no MobileNetV2 in the network.
    let m = message(&igev, &dir.path().join("none.pth"));
    assert!(m.contains("train.feature_init") && m.contains("none.pth") && m.contains("no such file"), "{m}");
    let m = message(&common::tiny_model(), &wide);
    assert!(m.contains("train.feature_init") && m.contains("mobilenet-pyramid"), "{m}");
    // A PyTorch file of another network: its keys are not timm's.
    if let Some(shared) =
        dgstereo_core::shared::shared_dir_for_test("igev_feature_init_pth", "golden/raft_stereo_random.pth")
    {
        let m = message(&igev, &shared.join("golden/raft_stereo_random.pth"));
        assert!(m.contains("raft_stereo_random.pth") && m.contains("missing key 'conv_stem.weight'"), "{m}");
    }
}

/// The loss reads the upsampled initial disparity: one step moves the volume's classifier and the
/// initial superpixel heads, which nothing else trains (the loop detaches its state); without
/// the term they stay bit for bit. The trunk's running statistics never train.
#[test]
fn the_initial_term_alone_trains_the_classifier() {
    let device = default_device();
    let parts = smoke_parts(None, 2, 2);
    let pairs = TrainingData::new(&parts.data, &parts.train).unwrap().batch(0, 1).unwrap();
    let step = |parts: TrainParts| {
        let mut trainer = Trainer::new(parts, &device).unwrap();
        let before = common::weights(&trainer.inference_model());
        let batch = to_tensors(&pairs, trainer.autodiff_device()).unwrap();
        let mut seen = None;
        let mut observe = |i: dgstereo_train::StepInternals<'_>| seen = i.initial.map(|t| t.dims());
        trainer.step_on(&batch, Some(&mut observe)).unwrap();
        (before, common::weights(&trainer.inference_model()), seen)
    };
    let (before, after, initial) = step(parts.clone());
    assert_eq!(initial, Some([1, 1, common::SIZE[0], common::SIZE[1]]), "the initial disparity at full resolution");
    for trains in
        ["geometry.classifier.", "superpixel.spx_4.", "superpixel.spx.", "superpixel.spx_gru.", "encoder.feature."]
    {
        assert!(!common::identical_under(&before, &after, trains), "{trains} did not train");
    }
    assert!(common::identical_under(&before, &after, "encoder.feature.bn1.running_mean"));
    let LossConfig::SequenceL1 { gamma, max_disparity, gamma_adjustment, .. } = parts.loss else { unreachable!() };
    let initial_disparity = InitialDisparityTerm::None;
    let without = TrainParts {
        loss: LossConfig::SequenceL1 { gamma, max_disparity, gamma_adjustment, initial_disparity },
        ..parts
    };
    let (before, after, _) = step(without);
    assert!(common::identical_under(&before, &after, "geometry.classifier."));
    assert!(common::identical_under(&before, &after, "superpixel.spx."));
    assert!(!common::identical_under(&before, &after, "superpixel.spx_gru."));
}

#[test]
fn a_smoke_run_checkpoints_and_resumes_bit_exactly() {
    let device = default_device();
    let dir = tempfile::tempdir().unwrap();
    // timm's ImageNet checkpoint is a PyTorch file: a plain state dict, no prefix.
    let file = dir.path().join("mobilenetv2_100_ra.pth");
    official_pth::write_pth(&timm_state(|_, shape| Some(shape)), "", &file);
    let parts = smoke_parts(Some(&file), 3, 2);
    let a = common::resumed_run_matches_uninterrupted(parts.clone(), &device, dir.path());
    // Three steps moved the network away from its start, the ImageNet trunk included.
    let trainer = Trainer::new(parts, &device).unwrap();
    assert!(trainer.notices().iter().any(|n| n.starts_with("train.feature_init:")), "{:?}", trainer.notices());
    let fresh = common::weights(&trainer.inference_model());
    let file_state = timm_state(|_, shape| Some(shape));
    let file_values = &file_state.iter().find(|t| t.key == "blocks.4.1.conv_dw.weight").unwrap().values;
    assert_eq!(&values_of(&fresh, "encoder.feature.block3.1.1.conv_dw.weight"), file_values, "the .pth file loaded");
    assert!(!common::identical_under(&a, &fresh, "encoder.feature.block3."));
    assert!(!common::identical_under(&a, &fresh, "geometry.classifier."));
}
