//! Reading the RAFT-Stereo configuration from a checkpoint's tensors.
//!
//! The two golden checkpoints (`../shared/golden/raft_stereo_random.pth`, the default
//! architecture, and `raft_stereo_realtime_random.pth`, the realtime one) detect as their
//! README describes them; the official state dict of a model built with each variant
//! (shared backbone, n_downsample, GRU levels, context norm, correlation levels and radius,
//! hidden, feature and trunk widths) detects as that variant; a state dict altered so that no
//! configuration fits is an error naming the keys that disagree.

use dgstereo_core::default_device;
use dgstereo_core::shared::shared_dir_for_test;
use dgstereo_model::ModelConfig;
use dgstereo_model::checkpoint_config::{OfficialPreset, config_from_keys, correlation_split, detect};
use dgstereo_model::encoder::{EncoderLayout, NormKind};
use dgstereo_model::official_keys::{KeyShape, model_official_keys};

fn official_keys(config: &ModelConfig) -> Vec<KeyShape> {
    model_official_keys(&config.init(&default_device()).expect("a valid variant"))
}

#[test]
fn golden_default_checkpoint_detects_as_the_default_configuration() {
    let file = "golden/raft_stereo_random.pth";
    let Some(shared) = shared_dir_for_test("golden_default_checkpoint_detects_as_the_default_configuration", file)
    else {
        return;
    };
    let detected = detect(&shared.join(file), &default_device()).expect("the default checkpoint detects");
    assert_eq!(detected.model, ModelConfig::default(), "{detected}");
    assert_eq!(detected.preset, OfficialPreset::Default);
    assert_eq!(detected.valid_iters, 32);
}

#[test]
fn golden_realtime_checkpoint_detects_as_the_realtime_configuration() {
    let file = "golden/raft_stereo_realtime_random.pth";
    let Some(shared) = shared_dir_for_test("golden_realtime_checkpoint_detects_as_the_realtime_configuration", file)
    else {
        return;
    };
    let detected = detect(&shared.join(file), &default_device()).expect("the realtime checkpoint detects");
    let mut expected = ModelConfig::default();
    expected.encoder.layout = EncoderLayout::SharedBackbone;
    expected.updater.n_downsample = 3;
    expected.updater.n_gru_layers = 2;
    expected.updater.slow_fast_gru = true;
    assert_eq!(detected.model, expected, "{detected}");
    assert_eq!(detected.preset, OfficialPreset::Realtime);
    assert_eq!(detected.valid_iters, 7);
    let line = detected.to_string();
    assert!(line.contains("shared backbone") && line.contains("7 iterations"), "{line}");
}

/// A small model (narrow trunk) with one option changed by `change`.
fn variant(change: impl FnOnce(&mut ModelConfig)) -> ModelConfig {
    let mut c = ModelConfig::default();
    c.encoder.trunk_dims = [16, 24, 32];
    c.encoder.feature_dim = 48;
    c.updater.hidden_dims = [32; 3];
    change(&mut c);
    c
}

#[test]
fn every_variant_detects_as_itself() {
    let variants = [
        variant(|_| {}),
        variant(|c| c.encoder.layout = EncoderLayout::SharedBackbone),
        variant(|c| c.updater.n_downsample = 3),
        variant(|c| c.updater.n_gru_layers = 1),
        variant(|c| c.updater.n_gru_layers = 2),
        variant(|c| c.encoder.context_norm = NormKind::Group),
        variant(|c| c.encoder.context_norm = NormKind::Instance),
        variant(|c| (c.correlation.levels, c.correlation.radius) = (2, 4)),
        variant(|c| (c.correlation.levels, c.correlation.radius) = (4, 2)),
        variant(|c| (c.correlation.levels, c.correlation.radius) = (2, 3)),
        variant(|c| c.updater.hidden_dims = [24; 3]),
        variant(|c| c.encoder.feature_dim = 64),
        variant(|c| {
            c.encoder.layout = EncoderLayout::SharedBackbone;
            c.updater.n_downsample = 3;
            c.updater.n_gru_layers = 2;
            c.encoder.context_norm = NormKind::Group;
        }),
    ];
    for config in variants {
        let detected = config_from_keys(&official_keys(&config), &default_device())
            .unwrap_or_else(|e| panic!("{config:?} does not detect: {e}"));
        assert_eq!(detected.model, config, "{detected}");
        assert_eq!(detected.preset, OfficialPreset::Custom, "narrow widths are no official preset");
    }
}

#[test]
fn the_official_architectures_get_their_presets() {
    let mut realtime = ModelConfig::default();
    realtime.encoder.layout = EncoderLayout::SharedBackbone;
    realtime.updater.n_downsample = 3;
    realtime.updater.n_gru_layers = 2;
    let detected = config_from_keys(&official_keys(&realtime), &default_device()).unwrap();
    assert_eq!(detected.preset, OfficialPreset::Realtime);
    assert!(detected.model.updater.slow_fast_gru);
    assert_eq!(detected.valid_iters, 7);

    let mut rvc = ModelConfig::default();
    rvc.encoder.context_norm = NormKind::Instance;
    let detected = config_from_keys(&official_keys(&rvc), &default_device()).unwrap();
    assert_eq!(detected.preset, OfficialPreset::InstanceContext);
    assert_eq!(detected.model, rvc);
    assert_eq!(detected.valid_iters, 32);
}

#[test]
fn a_parameterless_context_norm_detects_as_instance() {
    // `none` and `instance` store the same tensors (none); the official checkpoints use instance.
    let config = variant(|c| c.encoder.context_norm = NormKind::None);
    let detected = config_from_keys(&official_keys(&config), &default_device()).unwrap();
    assert_eq!(detected.model.encoder.context_norm, NormKind::Instance);
}

#[test]
fn correlation_channels_split_as_the_official_levels_and_radius_where_possible() {
    assert_eq!(correlation_split(36), Some((4, 4)));
    assert_eq!(correlation_split(18), Some((2, 4)));
    assert_eq!(correlation_split(20), Some((4, 2)));
    assert_eq!(correlation_split(14), Some((2, 3)));
    assert_eq!(correlation_split(5), Some((1, 2)));
    assert_eq!(correlation_split(16), None);
}

/// The error of detecting `keys`.
fn detection_error(keys: &[KeyShape]) -> String {
    match config_from_keys(keys, &default_device()) {
        Ok(c) => panic!("detected {c} from an inconsistent state dict"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn inconsistent_state_dicts_are_errors_naming_the_keys() {
    let base = official_keys(&variant(|_| {}));

    // A GRU whose input width fits no level count.
    let mut keys = base.clone();
    let gru = keys.iter_mut().find(|(k, _)| k == "update_block.gru08.convz.weight").unwrap();
    gru.1[1] += 8;
    let e = detection_error(&keys);
    assert!(e.contains("update_block.gru08.convz.weight"), "{e}");

    // Both a feature encoder and a shared backbone's head.
    let mut keys = base.clone();
    keys.extend(
        official_keys(&variant(|c| c.encoder.layout = EncoderLayout::SharedBackbone))
            .into_iter()
            .filter(|(k, _)| k.starts_with("conv2.")),
    );
    let e = detection_error(&keys);
    assert!(e.contains("'fnet.*'") && e.contains("'conv2.*'"), "{e}");

    // One block's batch statistics missing: its norm disagrees with cnet.norm1's.
    let keys: Vec<KeyShape> = base.iter().filter(|(k, _)| k != "cnet.layer2.1.norm2.running_var").cloned().collect();
    let e = detection_error(&keys);
    assert!(e.contains("cnet.layer2.1.norm2.running_var"), "{e}");

    // A key no configuration has, and a mask head of no upsampling factor.
    let mut keys = base.clone();
    keys.push(("update_block.gru64.convz.weight".into(), vec![32, 64, 3, 3]));
    let e = detection_error(&keys);
    assert!(e.contains("unexpected key 'update_block.gru64.convz.weight'"), "{e}");
    let mut keys = base.clone();
    keys.iter_mut().find(|(k, _)| k == "update_block.mask.2.weight").unwrap().1[0] = 100;
    let e = detection_error(&keys);
    assert!(e.contains("update_block.mask.2.weight"), "{e}");

    // Hidden widths the reference cannot run (`context_zqr_convs.0` needs hidden_dims[0] = [2]).
    let keys = official_keys(&variant(|c| c.updater.hidden_dims = [24, 32, 32]));
    let e = detection_error(&keys);
    assert!(e.contains("update_block.gru32.convz.weight"), "{e}");

    // No state dict at all.
    let e = detection_error(&[]);
    assert!(e.contains("fnet") && e.contains("missing key"), "{e}");
}
