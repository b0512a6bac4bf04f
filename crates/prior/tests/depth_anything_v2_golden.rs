//! Depth Anything V2 (ViT-S, random weights) against the official code's activations in
//! `shared/golden`, and strict checkpoint loading.

use std::path::PathBuf;

use dgstereo_core::shared::shared_dir_for_test;
use dgstereo_prior::depth_anything::checkpoint::{checkpoint_keys, encoder_from_keys, model_keys};
use dgstereo_prior::{DepthAnythingV2, DepthAnythingV2Encoder, PriorConfig, verify_depth_anything_v2};

const WEIGHTS: &str = "golden/depth_anything_v2_vits_random.pth";
const ACTIVATIONS: &str = "golden/depth_anything_v2_vits_random.activations.safetensors";

fn golden(test: &str) -> Option<(PathBuf, PathBuf)> {
    let shared = shared_dir_for_test(test, WEIGHTS)?;
    Some((shared.join(WEIGHTS), shared.join(ACTIVATIONS)))
}

#[test]
fn vits_reproduces_official_activations() {
    let Some((weights, reference)) = golden("vits_reproduces_official_activations") else { return };
    let device = dgstereo_core::default_device();
    let report = verify_depth_anything_v2(&weights, &reference, &device).expect("verification runs");
    println!("{report}");
    assert_eq!(report.encoder, DepthAnythingV2Encoder::Vits);
    // Every reference tensor is compared: 4 layers x (tokens, cls) + depth.
    assert_eq!(report.comparisons.len(), 9);
    assert!(report.comparisons.iter().all(|c| c.reference_range > 0.0));
    assert!(report.passed, "{report}");
    assert!(report.to_string().lines().last().unwrap().starts_with("depth max abs error: "));
}

#[test]
fn checkpoint_has_the_official_parameter_count_and_loads_completely() {
    let Some((weights, _)) = golden("checkpoint_has_the_official_parameter_count") else { return };
    let keys = checkpoint_keys(&weights).unwrap();
    assert_eq!(keys.len(), 239);
    let params: usize = keys.iter().map(|(_, s)| s.iter().product::<usize>()).sum();
    assert_eq!(params, 24_785_089);
    let model =
        DepthAnythingV2::load(DepthAnythingV2Encoder::Vits, &weights, &dgstereo_core::default_device()).unwrap();
    use burn::module::Module;
    assert_eq!(model.num_params(), params);
}

/// The state dict a built model gives (`model_keys`, which the ViT-B and ViT-L checks use) is
/// the official checkpoint's, key for key and shape for shape.
#[test]
fn a_built_model_has_the_official_state_dict() {
    let Some((weights, _)) = golden("a_built_model_has_the_official_state_dict") else { return };
    let mut official = checkpoint_keys(&weights).unwrap();
    official.sort();
    let built = model_keys(&DepthAnythingV2::new(DepthAnythingV2Encoder::Vits, &dgstereo_core::default_device()));
    assert_eq!(built, official);
    assert_eq!(encoder_from_keys(&official), Ok(DepthAnythingV2Encoder::Vits));
}

#[test]
fn a_checkpoint_of_another_size_is_an_error_naming_a_key() {
    let Some((weights, _)) = golden("a_checkpoint_of_another_size_is_an_error") else { return };
    let err = DepthAnythingV2::load(DepthAnythingV2Encoder::Vitb, &weights, &dgstereo_core::default_device())
        .unwrap_err()
        .to_string();
    assert!(err.contains("depth_anything_v2_vits_random.pth"), "{err}");
    assert!(err.contains("key '"), "{err}");
}

#[test]
fn the_provider_rejects_a_checkpoint_of_another_encoder_naming_the_key() {
    let Some((weights, _)) = golden("the_provider_rejects_a_checkpoint_of_another_encoder") else { return };
    let wrong = PriorConfig::DepthAnythingV2 { weights, encoder: Some(DepthAnythingV2Encoder::Vitl), input_size: 518 };
    let err = wrong.init(&dgstereo_core::default_device()).unwrap_err().to_string();
    assert!(err.contains("prior.encoder") && err.contains("vitl") && err.contains("vits"), "{err}");
}
