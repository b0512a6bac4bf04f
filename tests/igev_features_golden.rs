//! Conformance of IGEV-Stereo's encoder side and superpixel upsampling with the official code.
//!
//! The numbers come from `../shared/golden/igev_stereo_seeded.activations.safetensors`: the
//! official IGEV-Stereo (gangweiX/IGEV, `IGEV-Stereo/core/`, unchanged; timm 0.5.4's
//! `mobilenetv2_100` built without its ImageNet weights), `demo_imgs.py`'s arguments, float32 on
//! CPU, a 96x128 pair, 4 iterations, seeded weights (`seeded_weights.py`; see
//! `../shared/golden/README.md`). The modules load the rebuilt weights through their official-key
//! renames; where a module's input is another module's output (the update block's mask
//! features, the volume's classifier), the recorded tensor is fed.

use std::path::{Path, PathBuf};

use burn::store::burn_pack::Tensor as PackTensor;
use burn::store::{BurnToPyTorchAdapter, KeyRemapper, ModuleSnapshot, PyTorchToBurnAdapter, bridge};
use burn::tensor::activation::softmax;
use burn::tensor::{Device, Tensor, TensorData};
use dgstereo_core::default_device;
use dgstereo_core::tensor::{from_vec, to_vec};
use dgstereo_encoder::{EncoderConfig, EncoderLayout, Encoders, PyramidEncoders};
use dgstereo_model::official_keys::{Family, ignored_by_loader};
use dgstereo_model::seeded::golden_state_dict;
use dgstereo_model::verify::{ReferenceTensors, read_reference};
use dgstereo_suite::shared_dir_for_test;
use dgstereo_updater::superpixel::{SuperpixelUpsampler, context_upsample};

const GOLDEN: &str = "golden/igev_stereo_seeded.activations.safetensors";
/// Tolerance on features, relative to the reference tensor's largest magnitude.
const FEATURE_TOLERANCE: f32 = 1e-4;
/// Tolerance on full-resolution disparities, in pixels.
const DISPARITY_TOLERANCE: f32 = 1e-4;

fn golden(test: &str) -> Option<PathBuf> {
    Some(shared_dir_for_test(test, GOLDEN)?.join(GOLDEN))
}

/// `module`, which the model holds at `place` (`encoder.`), with the golden's seeded tensors whose
/// keys start with one of `prefixes`, renamed by IGEV-Stereo's table; every parameter must come
/// from the file and every tensor must land (the keys the loader ignores aside).
fn load<M: ModuleSnapshot>(mut module: M, golden: &Path, prefixes: &[&str], place: &str) -> M {
    let (state, _) = golden_state_dict(golden).unwrap();
    let tensors: Vec<PackTensor> = state
        .iter()
        .filter(|t| prefixes.iter().any(|p| t.key.starts_with(p)))
        .filter(|t| !ignored_by_loader(&t.key))
        .map(|t| bridge::from_data(TensorData::new(t.values.clone(), t.shape.clone()), t.key.clone(), None))
        .collect();
    let count = tensors.len();
    let mut renames = Family::IgevStereo.load_patterns();
    renames.push((format!("^{}", place.replace('.', r"\.")), String::new()));
    let (tensors, _) = KeyRemapper::from_patterns(renames).unwrap().remap(tensors);
    let result = module.apply(tensors, None, Some(Box::new(PyTorchToBurnAdapter)), true);
    assert!(result.errors.is_empty(), "{:?}", result.errors);
    assert!(result.missing.is_empty(), "parameters not in the file: {:?}", result.missing);
    assert!(result.unused.is_empty(), "keys that landed nowhere: {:?}", result.unused);
    assert!(count > 0);
    module
}

struct Reference {
    tensors: ReferenceTensors,
    device: Device,
}

impl Reference {
    fn get<const D: usize>(&self, key: &str) -> Tensor<D> {
        let (shape, values) = self.tensors.get(key).unwrap_or_else(|| panic!("no {key} in the golden"));
        from_vec(values.clone(), shape.as_slice().try_into().unwrap_or_else(|_| panic!("{key}: rank")), &self.device)
    }

    /// The largest error of `actual` against `key`, relative to the reference's largest magnitude.
    fn relative_error(&self, key: &str, actual: Tensor<4>) -> f32 {
        let (shape, expected) = &self.tensors[key];
        assert_eq!(&actual.dims().to_vec(), shape, "{key}: shape");
        let actual = to_vec(actual);
        let error = actual.iter().zip(expected).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
        error / expected.iter().map(|v| v.abs()).fold(0.0f32, f32::max).max(1e-6)
    }

    fn assert_close(&self, key: &str, actual: Tensor<4>) {
        let error = self.relative_error(key, actual);
        println!("{key}: relative error {error:.2e}");
        assert!(error <= FEATURE_TOLERANCE, "{key} is off by {error:.2e} of its largest magnitude");
    }

    /// The image `key` as the encoders see it, `2·x/255 - 1`.
    fn image(&self, key: &str) -> Tensor<4> {
        self.get::<4>(key).div_scalar(255.0).mul_scalar(2.0).sub_scalar(1.0)
    }
}

fn reference(path: &Path) -> Reference {
    Reference { tensors: read_reference(path).unwrap(), device: default_device() }
}

/// The IGEV encoders, built from the configuration variant and loaded with the seeded weights.
fn encoders(path: &Path, device: &Device) -> PyramidEncoders {
    let config = EncoderConfig { layout: EncoderLayout::MobilenetPyramid, ..Default::default() };
    let Encoders::Pyramid(encoders) = config.init([128; 3], 2, None, device).unwrap() else {
        panic!("the mobilenet pyramid builds the pyramid layout")
    };
    load(encoders, path, &["feature.", "stem_2.", "stem_4.", "cnet."], "encoder.")
}

#[test]
fn igev_feature_pyramid_stems_and_context_match() {
    let Some(path) = golden("igev_feature_pyramid_stems_and_context_match") else { return };
    let r = reference(&path);
    let encoders = encoders(&path, &r.device);
    for (call, view) in [(0, "input.left"), (1, "input.right")] {
        let levels = encoders.feature.forward(r.image(view));
        for (l, level) in levels.into_iter().enumerate() {
            r.assert_close(&format!("feature.call{call}.{l}"), level);
        }
        let stem_2x = encoders.stem_2.forward(r.image(view));
        r.assert_close(&format!("stem_2.call{call}"), stem_2x.clone());
        r.assert_close(&format!("stem_4.call{call}"), encoders.stem_4.forward(stem_2x));
    }
    let context = encoders.cnet.context(r.image("input.left"), 3);
    for (l, [hidden, context]) in context.levels.into_iter().enumerate() {
        r.assert_close(&format!("cnet.call0.{l}.0"), hidden);
        r.assert_close(&format!("cnet.call0.{l}.1"), context);
    }
}

/// The official soft-argmin initial disparity at 1/4 from the recorded classifier output
/// (`disparity_regression(softmax(classifier(volume)))`), which the volume's side computes.
fn initial_disparity(r: &Reference) -> Tensor<4> {
    let logits: Tensor<5> = r.get("classifier.call0");
    let [n, _, d, h, w] = logits.dims();
    let prob = softmax(logits.reshape([n, d, h, w]), 1);
    let values = from_vec((0..d).map(|i| i as f32).collect(), [1, d, 1, 1], &r.device);
    (prob * values).sum_dim(1)
}

/// The largest absolute difference, in pixels.
fn pixel_error(r: &Reference, key: &str, actual: Tensor<4>) -> f32 {
    let (shape, expected) = &r.tensors[key];
    assert_eq!(&actual.dims().to_vec(), shape, "{key}: shape");
    to_vec(actual).iter().zip(expected).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max)
}

#[test]
fn igev_superpixel_upsampling_matches() {
    let Some(path) = golden("igev_superpixel_upsampling_matches") else { return };
    let r = reference(&path);
    let prefixes = ["spx.", "spx_2.", "spx_4.", "spx_2_gru.", "spx_gru."];
    let up = load(SuperpixelUpsampler::new(&r.device), &path, &prefixes, "superpixel.");
    let stem_2x: Tensor<4> = r.get("stem_2.call0");
    let features = Tensor::cat(vec![r.get("feature.call0.0"), r.get("stem_4.call0")], 1);

    // The initial disparity's head, module by module, then the weights it gives.
    let x = up.spx_4.forward(features.clone());
    r.assert_close("spx_4.call0", x.clone());
    let x = up.spx_2.forward(x, stem_2x.clone());
    r.assert_close("spx_2.call0", x.clone());
    r.assert_close("spx.call0", up.spx.forward(x));
    let initial = initial_disparity(&r);
    let weights = up.initial_weights(features, stem_2x.clone());
    let error = pixel_error(&r, "disparity.init", context_upsample(initial.clone(), weights));
    println!("disparity.init: {error:.2e} px");
    assert!(error <= DISPARITY_TOLERANCE, "disparity.init off by {error} px");
    // Nearest upsampling instead of the weighted neighbourhood is far off: the comparison sees
    // the weights.
    let [n, _, h, w] = initial.dims();
    let nearest = initial.clone().mul_scalar(4.0).reshape([n, 1, h, 1, w, 1]).expand([n, 1, h, 4, w, 4]);
    let nearest_error = pixel_error(&r, "disparity.init", nearest.reshape([n, 1, 4 * h, 4 * w]));
    assert!(nearest_error > 100.0 * DISPARITY_TOLERANCE, "nearest upsampling within {nearest_error} px");

    // The iterations' head on the update block's recorded mask features; the disparity at 1/4
    // is the initial one plus the recorded updates so far.
    let mut disparity = initial;
    for k in 0..4 {
        let mask = r.get::<4>(&format!("update_block.call{k}.1"));
        let logits = up.spx_gru.forward(up.spx_2_gru.forward(mask.clone(), stem_2x.clone()));
        r.assert_close(&format!("spx_gru.call{k}"), logits);
        disparity = disparity + r.get::<4>(&format!("update_block.call{k}.2"));
        let up_disparity = context_upsample(disparity.clone(), up.iteration_weights(mask, stem_2x.clone()));
        let error = pixel_error(&r, &format!("disparity.iter{k}"), up_disparity);
        println!("disparity.iter{k}: {error:.2e} px");
        assert!(error <= DISPARITY_TOLERANCE, "disparity.iter{k} off by {error} px");
    }
}

/// Our module paths, at their place in the model, through IGEV-Stereo's table are the official
/// keys of these modules, each once (the keys the loader ignores aside): the listing of an IGEV
/// checkpoint's keys can be derived from the modules.
#[test]
fn igev_module_paths_map_back_to_the_official_keys() {
    let Some(path) = golden("igev_module_paths_map_back_to_the_official_keys") else { return };
    let device = default_device();
    let (state, _) = golden_state_dict(&path).unwrap();
    let official = |prefixes: &[&str]| {
        let mut keys: Vec<(String, Vec<usize>)> = state
            .iter()
            .filter(|t| prefixes.iter().any(|p| t.key.starts_with(p)))
            .filter(|t| !ignored_by_loader(&t.key))
            .map(|t| (t.key.clone(), t.shape.clone()))
            .collect();
        keys.sort();
        keys
    };
    let ours = |module: &dyn Fn() -> Vec<PackTensor>, place: &str| {
        let mut keys: Vec<(String, Vec<usize>)> = module()
            .iter()
            .map(|t| (Family::IgevStereo.official_key_of_module_path(&format!("{place}{}", t.name)), t.shape.to_vec()))
            .collect();
        keys.sort();
        keys
    };
    let config = EncoderConfig { layout: EncoderLayout::MobilenetPyramid, ..Default::default() };
    let Encoders::Pyramid(encoders) = config.init([128; 3], 2, None, &device).unwrap() else { unreachable!() };
    let encoders = || encoders.collect(None, Some(Box::new(BurnToPyTorchAdapter)), false);
    let encoder_keys: Vec<_> = ours(&encoders, "encoder.");
    assert_eq!(encoder_keys, official(&["feature.", "stem_2.", "stem_4.", "cnet."]));
    let up = SuperpixelUpsampler::new(&device);
    let up = || up.collect(None, Some(Box::new(BurnToPyTorchAdapter)), false);
    assert_eq!(ours(&up, "superpixel."), official(&["spx.", "spx_2.", "spx_4.", "spx_2_gru.", "spx_gru."]));
}
