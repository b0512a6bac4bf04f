//! An IGEV-Stereo training experiment in a study: `ablate` (locally, as a Slurm array or under
//! MPI) runs every run through the same check before anything trains, so the official recipe
//! passes it once its ImageNet weights and its data are there, and fails naming the key when not.

use std::path::{Path, PathBuf};

use dgstereo_experiment::{DataSource, ExperimentConfig, SyntheticScenes, TrainingDataConfig, load};
use dgstereo_study::runs::{parts_of, run_folder};
use dgstereo_study::task::check_run;

fn recipe() -> ExperimentConfig {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../experiments/zoo/igev-train.toml");
    let mut runs = load(&path).unwrap_or_else(|e| panic!("{e}"));
    runs.remove(0).config
}

#[test]
fn the_igev_recipe_passes_the_study_check() {
    let out = tempfile::tempdir().unwrap();
    let mut config = recipe();
    config.validate().unwrap();
    let folder = run_folder(out.path(), &config.name);
    // SceneFlow is not on this machine: named before anything trains, then synthetic pairs stand
    // in for the data.
    let message = check_run(&parts_of(config.clone(), Some(2)), &config.benchmarks, &folder).unwrap_err().to_string();
    assert!(message.contains("data.sources[0].root"), "{message}");
    config.data = TrainingDataConfig {
        sources: vec![DataSource::Synthetic {
            weight: 1.0,
            scenes: SyntheticScenes { width: 64, height: 32, ..Default::default() },
            count: Some(2),
            lattices: None,
        }],
        ..TrainingDataConfig::default()
    };
    // Nor is the placeholder path of the ImageNet weights.
    let message = check_run(&parts_of(config.clone(), Some(2)), &config.benchmarks, &folder).unwrap_err().to_string();
    assert!(message.contains("train.feature_init") && message.contains("mobilenetv2_100_ra-b33bc2c4.pth"), "{message}");
    let weights = out.path().join("mobilenetv2_100_ra-b33bc2c4.pth");
    std::fs::write(&weights, b"the check opens no weights file, it finds it").unwrap();
    config.train.feature_init = Some(weights);
    config.validate().unwrap();
    check_run(&parts_of(config.clone(), Some(2)), &config.benchmarks, &folder).unwrap();
    config.train.feature_init = Some(PathBuf::from("../weights/none.pth"));
    let message = check_run(&parts_of(config.clone(), Some(2)), &config.benchmarks, &folder).unwrap_err().to_string();
    assert!(message.contains("train.feature_init") && message.contains("none.pth"), "{message}");
}
