//! Conformance of DEFOM-Stereo with the official PyTorch code.
//!
//! The numbers come from `../shared/golden/defom_stereo_vits_seeded.activations.safetensors`:
//! the official DEFOM-Stereo (Insta360-Research-Team/DEFOM-Stereo, `core/`, unchanged), ViT-S,
//! `demo.py`'s arguments, run in float32 on CPU by `make_defom_golden.py` on a 96x128 pair for
//! 6 iterations of which 3 scale iterations, with seeded weights (every tensor a function of its
//! key and shape, `seeded_weights.py`; see `../shared/golden/README.md`). The test rebuilds the
//! weights from the file's metadata, reads the configuration from their keys and shapes alone,
//! loads them through the official-checkpoint loader and compares every recorded tensor.

use std::path::PathBuf;

use dgstereo_core::default_device;
use dgstereo_model::InitialDisparity;
use dgstereo_model::checkpoint_config::{self, OfficialPreset, config_from_keys};
use dgstereo_model::verify_defom::{DISPARITY_TOLERANCE, verify_defom};
use dgstereo_suite::shared_dir_for_test;

#[path = "support/official_pth.rs"]
mod official_pth;
#[path = "support/seeded_golden.rs"]
mod seeded_golden;

use seeded_golden::{SeededGolden, keys_of, zoo_model};

const GOLDEN: &str = "golden/defom_stereo_vits_seeded.activations.safetensors";

fn golden(test: &str) -> Option<PathBuf> {
    Some(shared_dir_for_test(test, GOLDEN)?.join(GOLDEN))
}

#[test]
fn every_defom_reference_tensor_matches() {
    let Some(reference) = golden("every_defom_reference_tensor_matches") else { return };
    let report = verify_defom(&reference, &default_device()).expect("verification runs");
    println!("{report}");
    assert!(report.unmatched.is_empty(), "keys not produced: {:?}", report.unmatched);
    // Depth Anything's 6 outputs, the encoder's 6, cnet's 6, fnet's 2, 3 scale and 3 normal
    // update blocks' 5 each and 6 disparities.
    assert_eq!(report.lines.len(), 56, "{report}");
    assert!(report.passed(), "some tensors are off:\n{report}");
    assert!(report.final_flow_error <= DISPARITY_TOLERANCE, "final disparity off by {}", report.final_flow_error);
}

/// The configuration comes from the tensors alone, and it is the zoo's DEFOM-Stereo ViT-S (with
/// the official evaluation's 8 scale iterations of 32).
#[test]
fn the_configuration_is_read_from_the_keys_and_shapes() {
    let Some(reference) = golden("the_configuration_is_read_from_the_keys_and_shapes") else { return };
    let keys = keys_of(&reference);
    let detected = config_from_keys(&keys, &default_device()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(detected.preset, OfficialPreset::Defom);
    assert_eq!(detected.valid_iters, 32);
    assert_eq!(detected.model, zoo_model("defom-vits.toml"));
    assert_eq!(detected.model.initial_disparity, InitialDisparity::scaled_inverse_depth());
    assert!(detected.to_string().contains("DEFOM-Stereo: Depth Anything V2 vits"), "{detected}");
    // 43,290,177 parameters, as the official model counts them (no buffers, aliases once).
    let parameters: usize = keys
        .iter()
        .filter(|(k, _)| !(k.ends_with("running_mean") || k.ends_with("running_var") || k == "mean" || k == "std"))
        .filter(|(k, _)| !k.contains("downsample.1."))
        .map(|(_, s)| s.iter().product::<usize>())
        .sum();
    assert_eq!(parameters, 43_290_177);
    // A key the configuration cannot explain is refused by name.
    let mut bad = keys.clone();
    bad.iter_mut().find(|(k, _)| k == "scale_update_block.encoder.convc1.weight").unwrap().1[1] = 45;
    let e = config_from_keys(&bad, &default_device()).unwrap_err().to_string();
    assert!(e.contains("scale_update_block.encoder.convc1.weight"), "{e}");
}

/// The comparison tells a wrong network from the official one: without the scale iterations, or
/// starting from zero instead of the scaled inverse depth, the final disparity is far off.
#[test]
fn the_reference_tells_the_scale_iterations_and_the_initialiser() {
    let Some(reference) = golden("the_reference_tells_the_scale_iterations_and_the_initialiser") else { return };
    let golden = SeededGolden::open(&reference);
    let run = |alter: &dyn Fn(&mut dgstereo_model::RaftStereo)| {
        let mut model = golden.model();
        model.scale_iters = 3;
        alter(&mut model);
        golden.disparity_error(&model, 6, Default::default(), "disparity.iter5")
    };
    let right = run(&|_| {});
    assert!(right <= DISPARITY_TOLERANCE, "the official configuration is off by {right}");
    let no_scale = run(&|m| m.scale_iters = 0);
    assert!(no_scale > 100.0 * DISPARITY_TOLERANCE, "without scale iterations within {no_scale}");
    let from_zero = run(&|m| m.initial_disparity = InitialDisparity::Zero {});
    assert!(from_zero > 100.0 * DISPARITY_TOLERANCE, "from zero within {from_zero}");
}

/// The seeded weights written as an official `.pth` (under `module.`, as the released
/// checkpoints are saved) load through the file loader with the configuration detected from the
/// file, and give the official code's disparity: the PyTorch reader's path (its key renames and
/// layouts) is the in-memory loader's.
#[test]
fn an_official_pth_file_loads_and_gives_the_reference_disparity() {
    let Some(reference) = golden("an_official_pth_file_loads_and_gives_the_reference_disparity") else { return };
    let golden = SeededGolden::open(&reference);
    let dir = tempfile::tempdir().unwrap();
    let pth = dir.path().join("defomstereo_vits_seeded.pth");
    official_pth::write_pth(&golden.state, "module.", &pth);
    let (mut model, detected) =
        checkpoint_config::load_detected(&pth, &default_device()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(detected.preset, OfficialPreset::Defom);
    model.scale_iters = 3;
    let error = golden.disparity_error(&model, 6, Default::default(), "disparity.iter5");
    assert!(error <= DISPARITY_TOLERANCE, "the .pth file's model is off by {error} px");
}
