//! A DEFOM-Stereo experiment in a study: `ablate` (locally, as a Slurm array or under MPI) runs
//! every run through the same check before anything trains, so the official recipe passes it
//! once its weights are resolved and its data is there, and fails naming the key when not.

use std::path::{Path, PathBuf};

use dgstereo_core::shared::shared_dir_for_test;
use dgstereo_experiment::{DataSource, ExperimentConfig, SyntheticScenes, TrainingDataConfig, load};
use dgstereo_study::runs::{parts_of, run_folder};
use dgstereo_study::task::check_run;

const DEPTH_ANYTHING: &str = "golden/depth_anything_v2_vits_random.pth";

fn recipe() -> ExperimentConfig {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../experiments/zoo/defom-vits-train.toml");
    let mut runs = load(&path).unwrap_or_else(|e| panic!("{e}"));
    runs.remove(0).config
}

#[test]
fn the_defom_recipe_passes_the_study_check() {
    let Some(shared) = shared_dir_for_test("defom_study_check", DEPTH_ANYTHING) else { return };
    let out = tempfile::tempdir().unwrap();
    let mut config = recipe();
    // SceneFlow is not on this machine: synthetic pairs stand in for the data.
    config.data = TrainingDataConfig {
        sources: vec![DataSource::Synthetic {
            weight: 1.0,
            scenes: SyntheticScenes { width: 64, height: 32, ..Default::default() },
            count: Some(2),
            lattices: None,
        }],
        ..TrainingDataConfig::default()
    };
    let folder = run_folder(out.path(), &config.name);
    // The catalog name is resolved by the front end before the check; left as a name it is refused.
    let unresolved = parts_of(config.clone(), Some(2));
    let message = check_run(&unresolved, &config.benchmarks, &folder).unwrap_err().to_string();
    assert!(message.contains("train.monocular_init") && message.contains("depth-anything-v2-small"), "{message}");
    // Resolved to its file, the run passes.
    config.train.monocular_init = Some(shared.join(DEPTH_ANYTHING));
    check_run(&parts_of(config.clone(), Some(2)), &config.benchmarks, &folder).unwrap();
    // A file that is not there is named before anything trains.
    config.train.monocular_init = Some(PathBuf::from("../weights/depth_anything_v2_vits.pth"));
    let message = check_run(&parts_of(config.clone(), Some(2)), &config.benchmarks, &folder).unwrap_err().to_string();
    assert!(message.contains("train.monocular_init") && message.contains("depth_anything_v2_vits.pth"), "{message}");
}
