//! DEFOM-Stereo trained with its official recipe (`experiments/zoo/defom-vits-train.toml`):
//! the file holds `train_stereo.py`'s defaults, the Depth Anything V2 weights load into the
//! monocular network, its ViT and depth head stay bit for bit what they were loaded as while the
//! rest trains, every iteration (the scale ones first) is supervised, and a smoke-size run
//! checkpoints and resumes bit-exactly.

mod common;

use std::path::{Path, PathBuf};

use dgstereo_core::default_device;
use dgstereo_core::shared::shared_dir_for_test;
use dgstereo_experiment::{ExperimentConfig, load};
use dgstereo_loss::{GammaAdjustment, InitialDisparityTerm, LossConfig};
use dgstereo_train::batch::{TrainingData, to_tensors};
use dgstereo_train::{TrainParts, Trainer};

const DEPTH_ANYTHING: &str = "golden/depth_anything_v2_vits_random.pth";

fn recipe_file() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../experiments/zoo/defom-vits-train.toml")
}

fn recipe() -> ExperimentConfig {
    let mut runs = load(&recipe_file()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(runs.len(), 1);
    runs.remove(0).config
}

/// The recipe at smoke size: the official architecture, 3 iterations of which 2 scale
/// iterations, one 32x64 synthetic pair a step, the Depth Anything V2 file of `shared/golden`.
fn smoke_parts(weights: &Path, steps: usize) -> TrainParts {
    let mut config = recipe();
    let tiny = common::tiny_parts(steps, 3, 1e-3, Some(2), 1);
    config.model.updater.scale_update.as_mut().expect("DEFOM's scale update").iters = 2;
    config.train = dgstereo_experiment::TrainingConfig {
        monocular_init: Some(weights.to_path_buf()),
        frozen: config.train.frozen.clone(),
        ..tiny.train
    };
    config.data = tiny.data;
    TrainParts::from(config)
}

#[test]
fn the_recipe_file_holds_the_official_defaults() {
    let config = recipe();
    config.validate().unwrap();
    let t = &config.train;
    assert_eq!((t.steps, t.batch_size, t.crop, t.iters), (200_000, 8, [320, 736], 18));
    assert_eq!(config.model.updater.scale_update.as_ref().map(|s| s.iters), Some(8));
    assert_eq!((t.lr, t.weight_decay, t.eps, t.clip), (2e-4, 1e-5, 1e-8, 1.0));
    assert_eq!((t.warmup_fraction, t.schedule_extra_steps, t.seed), (0.01, 100, 1234));
    assert_eq!(t.monocular_init.as_deref(), Some(Path::new("depth-anything-v2-small")));
    assert_eq!(t.frozen, ["monocular.pretrained", "monocular.depth_head"]);
    assert_eq!(
        config.loss,
        LossConfig::SequenceL1 {
            gamma: 0.9,
            max_disparity: 700.0,
            gamma_adjustment: GammaAdjustment::DefomStereo,
            initial_disparity: InitialDisparityTerm::None,
        }
    );
    assert_eq!(config.data.sources.len(), 6);
}

#[test]
fn a_step_leaves_the_frozen_network_bit_identical_while_the_rest_moves() {
    let Some(shared) = shared_dir_for_test("defom_frozen_step", DEPTH_ANYTHING) else { return };
    let device = default_device();
    let parts = smoke_parts(&shared.join(DEPTH_ANYTHING), 4);
    let mut trainer = Trainer::new(parts.clone(), &device).unwrap();
    assert!(trainer.notices().iter().any(|n| n.starts_with("train.monocular_init:")), "{:?}", trainer.notices());
    let before = common::weights(&trainer.inference_model());
    let pairs = TrainingData::new(&parts.data, &parts.train).unwrap().batch(0, 1).unwrap();
    let batch = to_tensors(&pairs, trainer.autodiff_device()).unwrap();
    let (mut predictions, mut initial) = (0, true);
    let mut observe = |i: dgstereo_train::StepInternals<'_>| {
        predictions = i.predictions.len();
        initial = i.initial.is_some();
    };
    trainer.step_on(&batch, Some(&mut observe)).unwrap();
    // Every iteration is supervised, the two scale iterations included; the scaled inverse depth
    // the loop starts from is not handed to the loss (the official DEFOM loss does not read it).
    assert_eq!(predictions, 3);
    assert!(!initial);
    let after = common::weights(&trainer.inference_model());
    assert!(common::identical_under(&before, &after, "monocular.pretrained."));
    assert!(common::identical_under(&before, &after, "monocular.depth_head."));
    for trains in ["monocular.depth_feat.", "encoder.fnet.", "encoder.cnet.", "update_block.", "scale_update_block."] {
        assert!(!common::identical_under(&before, &after, trains), "{trains} did not train");
    }
    // Without `train.frozen` the same step changes the ViT: the check above can fail.
    let unfrozen =
        TrainParts { train: dgstereo_experiment::TrainingConfig { frozen: Vec::new(), ..parts.train }, ..parts };
    let mut trainer = Trainer::new(unfrozen, &device).unwrap();
    let batch = to_tensors(&pairs, trainer.autodiff_device()).unwrap();
    trainer.step_on(&batch, None).unwrap();
    assert!(!common::identical_under(&before, &common::weights(&trainer.inference_model()), "monocular.pretrained."));
}

#[test]
fn monocular_init_loads_the_vit_and_head_and_keeps_the_feature_trunk() {
    let Some(shared) = shared_dir_for_test("defom_monocular_init", DEPTH_ANYTHING) else { return };
    let device = default_device();
    let file = shared.join(DEPTH_ANYTHING);
    let seeded = |seed: u64, init: Option<&Path>| {
        let mut parts = smoke_parts(&file, 1);
        parts.train.seed = seed;
        parts.train.monocular_init = init.map(Path::to_path_buf);
        common::weights(&Trainer::new(parts, &device).unwrap().inference_model())
    };
    let (a, b, random) = (seeded(1, Some(&file)), seeded(2, Some(&file)), seeded(1, None));
    // The file decides the ViT and the depth head whatever the seed; the trunk keeps the seed's.
    assert!(common::identical_under(&a, &b, "monocular.pretrained."));
    assert!(common::identical_under(&a, &b, "monocular.depth_head."));
    assert!(!common::identical_under(&a, &random, "monocular.pretrained."));
    assert!(!common::identical_under(&a, &b, "monocular.depth_feat."));
    assert!(common::identical_under(&a, &random, "monocular.depth_feat."));

    // A file that does not fit: the error names the key, the file and what is wrong.
    let error = |init: PathBuf| {
        let mut parts = smoke_parts(&file, 1);
        parts.train.monocular_init = Some(init);
        Trainer::new(parts, &device).err().expect("the file does not fit").to_string()
    };
    let raft = shared.join("golden/raft_stereo_random.pth");
    if raft.exists() {
        let message = error(raft);
        assert!(message.contains("train.monocular_init"), "{message}");
        assert!(
            message.contains("raft_stereo_random.pth") && message.contains("missing key 'depth_head."),
            "{message}"
        );
        assert!(message.contains("not a Depth Anything V2 vits checkpoint"), "{message}");
    }
    let message = error(shared.join("golden/no_such_file.pth"));
    assert!(message.contains("train.monocular_init") && message.contains("no_such_file.pth"), "{message}");
}

#[test]
fn frozen_paths_and_monocular_init_are_checked() {
    let device = default_device();
    let mut parts = common::tiny_parts(1, 1, 1e-3, Some(1), 1);
    parts.train.frozen = vec!["monocular.pretrained".into()];
    let message = Trainer::new(parts.clone(), &device).err().expect("no monocular network").to_string();
    assert!(message.contains("train.frozen[0]") && message.contains("names no parameter"), "{message}");
    parts.train.frozen = vec!["encoder.fnet".into()];
    Trainer::new(parts.clone(), &device).unwrap();
    parts.train.frozen = vec!["fnet..conv1".into()];
    assert!(parts.train.validate().unwrap_err().to_string().contains("train.frozen[0]"));
    parts.train.frozen = Vec::new();
    parts.train.monocular_init = Some(PathBuf::from("depth_anything_v2_vits.pth"));
    let message = Trainer::new(parts, &device).err().expect("no monocular network").to_string();
    assert!(message.contains("train.monocular_init") && message.contains("no monocular network"), "{message}");
}

#[test]
fn a_smoke_run_checkpoints_and_resumes_bit_exactly() {
    let Some(shared) = shared_dir_for_test("defom_smoke_resume", DEPTH_ANYTHING) else { return };
    let device = default_device();
    let parts = smoke_parts(&shared.join(DEPTH_ANYTHING), 3);
    let dir = tempfile::tempdir().unwrap();
    let a = common::resumed_run_matches_uninterrupted(parts.clone(), &device, dir.path());
    // The frozen network is still the file's after three steps and a resume.
    let fresh = common::weights(&Trainer::new(parts, &device).unwrap().inference_model());
    assert!(common::identical_under(&a, &fresh, "monocular.pretrained."));
    assert!(!common::identical_under(&a, &fresh, "encoder.fnet."));
}
