//! IGEV-Stereo's geometry encoding volume, its lookup and its update block against the official
//! code, stage by stage.
//!
//! The numbers come from `../shared/golden/igev_stereo_seeded.activations.safetensors` (the
//! official IGEV-Stereo, `demo_imgs.py`'s arguments, float32 on CPU, seeded weights; see
//! `../shared/golden/README.md`). Each stage runs on the recorded outputs of the stages before it
//! (the feature pyramids and image stems for the volume; the context encoder's heads and the
//! recorded volume for the update block), with its weights rebuilt from the file's metadata, so
//! a mismatch points at the stage itself.

use std::path::{Path, PathBuf};

use burn::module::Module;
use burn::store::burn_pack::Tensor as PackTensor;
use burn::store::{KeyRemapper, ModuleSnapshot, PyTorchToBurnAdapter, bridge};
use burn::tensor::activation::{relu, softmax, tanh};
use burn::tensor::{Device, Int, Tensor, TensorData};
use dgstereo_core::default_device;
use dgstereo_core::tensor::{from_vec, to_vec};
use dgstereo_costvolume::{CombinedGeometryVolume, CorrelationImplementation, GeometryEncoding, GeometryVolume};
use dgstereo_model::seeded::golden_state_dict;
use dgstereo_model::updater::{
    GateContext, HeadOutput, MotionKind, MultiLevelUpdateBlock, Updater, UpdaterConfig, UpsamplingKind,
};
use dgstereo_model::verify::{FEATURE_TOLERANCE, ReferenceTensors, read_reference};
use dgstereo_suite::shared_dir_for_test;

const GOLDEN: &str = "golden/igev_stereo_seeded.activations.safetensors";

fn golden(test: &str) -> Option<PathBuf> {
    Some(shared_dir_for_test(test, GOLDEN)?.join(GOLDEN))
}

/// The seeded tensors `select` keeps, under the names it gives them, with `renames` applied,
/// loaded into `module`: every tensor must be used and, if `strict`, every parameter come from
/// the file.
fn load<M: ModuleSnapshot + Module>(
    mut module: M,
    path: &Path,
    select: impl Fn(&str) -> Option<String>,
    renames: &[(&str, &str)],
    strict: bool,
) -> M {
    let (state, _) = golden_state_dict(path).unwrap();
    let tensors: Vec<PackTensor> = state
        .iter()
        .filter(|t| !t.key.ends_with("num_batches_tracked"))
        .filter_map(|t| Some((select(&t.key)?, t)))
        .map(|(key, t)| bridge::from_data(TensorData::new(t.values.clone(), t.shape.clone()), key, None))
        .collect();
    let (tensors, _) = KeyRemapper::from_patterns(renames.to_vec()).unwrap().remap(tensors);
    let result = module.apply(tensors, None, Some(Box::new(PyTorchToBurnAdapter)), true);
    assert!(result.errors.is_empty(), "{:?}", result.errors);
    assert!(result.unused.is_empty(), "unused {:?}", result.unused);
    assert!(!strict || result.missing.is_empty(), "missing {:?}", result.missing);
    module
}

/// The seeded tensors under `prefix`, the prefix dropped.
fn under(prefix: &str) -> impl Fn(&str) -> Option<String> + '_ {
    move |key| key.strip_prefix(prefix).map(str::to_string)
}

/// The geometry encoding volume's modules, at the reference's top level, with the official
/// names of the feature gates' two layers.
fn geometry_volume(path: &Path, device: &Device) -> GeometryEncoding {
    let top = ["conv.", "desc.", "corr_stem.", "corr_feature_att.", "cost_agg.", "classifier."];
    let select = |key: &str| top.iter().any(|p| key.starts_with(p)).then(|| key.to_string());
    let renames = [(r"feat_att\.0\.", "reduce."), (r"feat_att\.1\.", "expand.")];
    load(GeometryVolume::default().init(device), path, select, &renames, true)
}

fn tensor<const D: usize>(refs: &ReferenceTensors, key: &str, device: &Device) -> Tensor<D> {
    let (shape, values) = refs.get(key).unwrap_or_else(|| panic!("no {key}"));
    from_vec(values.clone(), shape.as_slice().try_into().unwrap(), device)
}

/// The largest difference relative to the reference's largest magnitude.
fn relative_error<const D: usize>(actual: Tensor<D>, refs: &ReferenceTensors, key: &str) -> f32 {
    let (shape, expected) = &refs[key];
    assert_eq!(actual.dims().to_vec(), *shape, "{key}");
    let actual = to_vec(actual);
    let error = actual.iter().zip(expected).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    error / expected.iter().map(|v| v.abs()).fold(0.0f32, f32::max).max(1e-6)
}

fn assert_matches<const D: usize>(actual: Tensor<D>, refs: &ReferenceTensors, key: &str) {
    let error = relative_error(actual, refs, key);
    println!("{key}: relative error {error:.2e}");
    assert!(error <= FEATURE_TOLERANCE, "{key} off by {error} of its largest magnitude");
}

/// The left pyramid as the volume reads it (the 1/4 level with the image stem's channels), and
/// the right view's 1/4 level.
fn recorded_features(refs: &ReferenceTensors, device: &Device) -> (Vec<Tensor<4>>, Tensor<4>) {
    let quarter = |call: usize| {
        Tensor::cat(
            vec![
                tensor(refs, &format!("feature.call{call}.0"), device),
                tensor(refs, &format!("stem_4.call{call}"), device),
            ],
            1,
        )
    };
    let mut left = vec![quarter(0)];
    left.extend((1..4).map(|i| tensor(refs, &format!("feature.call0.{i}"), device)));
    (left, quarter(1))
}

#[test]
fn the_geometry_volume_matches_the_reference() {
    let Some(path) = golden("the_geometry_volume_matches_the_reference") else { return };
    let device = default_device();
    let refs = read_reference(&path).unwrap();
    let geometry = geometry_volume(&path, &device);
    let (left, right) = recorded_features(&refs, &device);
    let out = geometry.forward(&left, right);
    assert_matches(out.corr_stem, &refs, "corr_stem.call0");
    assert_matches(out.corr_feature_att, &refs, "corr_feature_att.call0");
    assert_matches(out.volume, &refs, "cost_agg.call0");
    assert_matches(out.logits.unsqueeze_dim::<5>(1), &refs, "classifier.call0");
}

/// The soft-argmin of the classifier's logits: `Σ_d softmax(logits)_d · d`.
fn soft_argmin(logits: Tensor<4>) -> Tensor<4> {
    let [_, d, _, _] = logits.dims();
    let device = logits.device();
    let values = Tensor::<1, Int>::arange(0..d as i64, &device).float().reshape([1, d, 1, 1]);
    (softmax(logits, 1) * values).sum_dim(1)
}

#[test]
fn the_update_block_matches_the_reference_on_the_recorded_volume() {
    let Some(path) = golden("the_update_block_matches_the_reference_on_the_recorded_volume") else { return };
    let device = default_device();
    let refs = read_reference(&path).unwrap();
    // Match features from the recorded pyramids, through the volume's own convolutions.
    let geometry = geometry_volume(&path, &device);
    let (left, right) = recorded_features(&refs, &device);
    let (match_left, match_right) = (geometry.match_features(left[0].clone()), geometry.match_features(right));
    let volume: Tensor<5> = tensor(&refs, "cost_agg.call0", &device);
    let combined = CombinedGeometryVolume::new(match_left, match_right, volume, 2, 4, CorrelationImplementation::Reg);
    assert_eq!(combined.channels(), 162);

    let config =
        UpdaterConfig { motion: MotionKind::Disparity, upsampling: UpsamplingKind::Superpixel, ..Default::default() };
    let block = MultiLevelUpdateBlock::new(&config, combined.channels(), HeadOutput::Delta, &device);
    // The reference's GRUs are named by their level (`gru04` at 1/4); ours by RAFT-Stereo's.
    let renames = [
        (r"^gru16\.", "gru32."),
        (r"^gru08\.", "gru16."),
        (r"^gru04\.", "gru08."),
        (r"^mask_feat_4\.0\.", "mask_feat_4.conv."),
    ];
    let block = load(block, &path, under("update_block."), &renames, true);

    let mut hidden: Vec<Tensor<4>> =
        (0..3).map(|i| tanh(tensor(&refs, &format!("cnet.call0.{i}.0"), &device))).collect();
    let gates: Vec<GateContext> = (0..3)
        .map(|i| {
            let conv = burn::nn::conv::Conv2dConfig::new([128, 384], [3, 3])
                .with_padding(burn::nn::PaddingConfig2d::Explicit(1, 1, 1, 1))
                .init(&device);
            let conv = load(conv, &path, under(&format!("context_zqr_convs.{i}.")), &[], true);
            GateContext::from_zqr(conv.forward(relu(tensor(&refs, &format!("cnet.call0.{i}.1"), &device))))
        })
        .collect();
    let logits: Tensor<5> = tensor(&refs, "classifier.call0", &device);
    let mut disparity = soft_argmin(logits.squeeze_dim::<4>(1));
    let [n, _, h, w] = disparity.dims();
    let coords0 = from_vec((0..n * h * w).map(|i| (i % w) as f32).collect(), [n, 1, h, w], &device);
    let calls = (0..).take_while(|k| refs.contains_key(&format!("update_block.call{k}.2"))).count();
    assert_eq!(calls, 4);
    for k in 0..calls {
        let corr = combined.lookup(coords0.clone(), disparity.clone());
        let update = block.step(&mut hidden, &gates, corr, disparity.clone(), None, &mut dgstereo_core::Probe::none());
        for (i, state) in hidden.iter().enumerate() {
            assert_matches(state.clone(), &refs, &format!("update_block.call{k}.0.{i}"));
        }
        assert_matches(block.upsample_mask(&hidden), &refs, &format!("update_block.call{k}.1"));
        assert_matches(update.prediction.clone(), &refs, &format!("update_block.call{k}.2"));
        disparity = update.apply(disparity);
    }
}
