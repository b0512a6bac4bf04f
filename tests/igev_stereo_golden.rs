//! Conformance of IGEV-Stereo with the official PyTorch code.
//!
//! The numbers come from `../shared/golden/igev_stereo_seeded.activations.safetensors`: the
//! official IGEV-Stereo (gangweiX/IGEV, `IGEV-Stereo/core/`, unchanged; timm 0.5.4's
//! `mobilenetv2_100` built without its ImageNet weights), `demo_imgs.py`'s arguments, run in
//! float32 on CPU by `make_igev_golden.py` on a 96x128 pair for 4 iterations, with seeded weights
//! (every tensor a function of its key and shape, `seeded_weights.py`; see
//! `../shared/golden/README.md`). The test rebuilds the weights from the file's metadata, reads
//! the configuration from their keys and shapes alone, loads them through the
//! official-checkpoint loader and compares every recorded tensor.

use std::path::PathBuf;

use dgstereo_core::default_device;
use dgstereo_core::tensor::{max_abs_diff, to_vec};
use dgstereo_costvolume::CorrelationImplementation;
use dgstereo_model::checkpoint_config::{self, OfficialPreset, config_from_keys, model_from_keys};
use dgstereo_model::verify_igev::{DISPARITY_TOLERANCE, verify_igev};
use dgstereo_model::{ForwardOptions, InitialDisparity, RaftStereo, checkpoint, padded_training_disparities};
use dgstereo_suite::shared_dir_for_test;

#[path = "support/official_pth.rs"]
mod official_pth;
#[path = "support/seeded_golden.rs"]
mod seeded_golden;

use seeded_golden::{SeededGolden, keys_of, zoo_model};

const GOLDEN: &str = "golden/igev_stereo_seeded.activations.safetensors";

fn golden(test: &str) -> Option<PathBuf> {
    Some(shared_dir_for_test(test, GOLDEN)?.join(GOLDEN))
}

#[test]
fn every_igev_reference_tensor_matches() {
    let Some(reference) = golden("every_igev_reference_tensor_matches") else { return };
    let report = verify_igev(&reference, &default_device()).expect("verification runs");
    println!("{report}");
    assert!(report.unmatched.is_empty(), "keys not produced: {:?}", report.unmatched);
    // Both views' 4 pyramid levels and 2 stems, the volume's 4 stages, the initial superpixel
    // weights' 3, cnet's 6, 4 update blocks' 5 each, 4 iterations' superpixel logits, the
    // initial and 4 iterated disparities.
    assert_eq!(report.lines.len(), 54, "{report}");
    assert!(report.passed(), "some tensors are off:\n{report}");
    assert!(report.final_flow_error <= DISPARITY_TOLERANCE, "final disparity off by {}", report.final_flow_error);
}

/// The configuration comes from the tensors alone, and it is the zoo's IGEV-Stereo (with the
/// official demo's 32 iterations).
#[test]
fn the_igev_configuration_is_read_from_the_keys_and_shapes() {
    let Some(reference) = golden("the_igev_configuration_is_read_from_the_keys_and_shapes") else { return };
    let keys = keys_of(&reference);
    let detected = config_from_keys(&keys, &default_device()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(detected.preset, OfficialPreset::Igev);
    assert_eq!(detected.valid_iters, 32);
    assert_eq!(detected.model, zoo_model("igev.toml"));
    assert_eq!(detected.model.initial_disparity, InitialDisparity::SoftArgmin {});
    assert!(detected.to_string().contains("IGEV-Stereo: geometry volume max_disp 192, 8 groups"), "{detected}");
    // 12,598,114 parameters, as the official model counts them (no buffers, aliases once).
    let parameters: usize = keys
        .iter()
        .filter(|(k, _)| !(k.ends_with("running_mean") || k.ends_with("running_var")))
        .filter(|(k, _)| !k.contains("downsample.1."))
        .map(|(_, s)| s.iter().product::<usize>())
        .sum();
    assert_eq!(parameters, 12_598_114);
    // A key the configuration cannot explain is refused by name.
    let mut bad = keys.clone();
    bad.iter_mut().find(|(k, _)| k == "update_block.encoder.convc1.weight").unwrap().1[1] = 160;
    let e = config_from_keys(&bad, &default_device()).unwrap_err().to_string();
    assert!(e.contains("update_block.encoder.convc1.weight"), "{e}");
    let mut bad = keys;
    bad.retain(|(k, _)| k != "cost_agg.conv1_up.conv.weight");
    let e = config_from_keys(&bad, &default_device()).unwrap_err().to_string();
    assert!(e.contains("cost_agg.conv1_up.conv.weight"), "{e}");
}

/// The comparison tells a wrong network from the official one: starting from zero instead of
/// the geometry volume's soft-argmin, the final disparity is far off.
#[test]
fn the_reference_tells_the_soft_argmin_start() {
    let Some(reference) = golden("the_reference_tells_the_soft_argmin_start") else { return };
    let golden = SeededGolden::open(&reference);
    let run = |alter: &dyn Fn(&mut dgstereo_model::RaftStereo)| {
        let mut model = golden.model();
        alter(&mut model);
        golden.disparity_error(&model, 4, Default::default(), "disparity.iter3")
    };
    let right = run(&|_| {});
    assert!(right <= DISPARITY_TOLERANCE, "the official configuration is off by {right}");
    let from_zero = run(&|m| m.initial_disparity = InitialDisparity::Zero {});
    assert!(from_zero > 100.0 * DISPARITY_TOLERANCE, "from zero within {from_zero}");
}

/// The seeded weights written as an official `.pth` (under `module.`, as the released
/// checkpoints are saved) load through the file loader with the configuration detected from the
/// file, and give the official code's disparity.
#[test]
fn an_official_igev_pth_file_loads_and_gives_the_reference_disparity() {
    let Some(reference) = golden("an_official_igev_pth_file_loads_and_gives_the_reference_disparity") else { return };
    let golden = SeededGolden::open(&reference);
    let dir = tempfile::tempdir().unwrap();
    let pth = dir.path().join("igev_sceneflow_seeded.pth");
    official_pth::write_pth(&golden.state, "module.", &pth);
    let (model, detected) = checkpoint_config::load_detected(&pth, &default_device()).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(detected.preset, OfficialPreset::Igev);
    let error = golden.disparity_error(&model, 4, Default::default(), "disparity.iter3");
    assert!(error <= DISPARITY_TOLERANCE, "the .pth file's model is off by {error} px");
    // The lookup's correlation half on the fly (`--corr alt`) gives the same disparity.
    let alt = ForwardOptions { implementation: Some(CorrelationImplementation::Alt), ..Default::default() };
    let error = golden.disparity_error(&model, 4, alt, "disparity.iter3");
    assert!(error <= DISPARITY_TOLERANCE, "with the on-the-fly correlation the model is off by {error} px");
}

/// A training pass also returns the official `init_disp`: the soft-argmin start upsampled by the
/// initial superpixel heads (`spx_4`, `spx_2`, `spx`), which IGEV-Stereo's loss supervises. Its
/// iterations are the inference pass's, and a start that is not the soft-argmin gives none.
#[test]
fn a_training_pass_returns_the_official_initial_disparity() {
    let Some(reference) = golden("a_training_pass_returns_the_official_initial_disparity") else { return };
    let golden = SeededGolden::open(&reference);
    let config = config_from_keys(&golden.keys, &default_device()).unwrap_or_else(|e| panic!("{e}")).model;
    let (left, right) = (golden.tensor("input.left"), golden.tensor("input.right"));
    let train =
        |model: &RaftStereo| padded_training_disparities(model, &config, left.clone(), right.clone(), None, 4).unwrap();
    let mut model = golden.model();
    let training = train(&model);
    let initial = training.initial.clone().expect("IGEV-Stereo's training pass gives its initial disparity");
    assert_eq!(initial.dims(), [1, 1, 96, 128]);
    let error = max_abs_diff(initial, golden.tensor("disparity.init"));
    assert!(error <= DISPARITY_TOLERANCE, "the initial disparity is off by {error} px");
    assert_eq!(training.iterations.len(), 4);
    for (k, disparity) in training.iterations.iter().enumerate() {
        let error = max_abs_diff(disparity.clone(), golden.tensor(&format!("disparity.iter{k}")));
        assert!(error <= DISPARITY_TOLERANCE, "iteration {k} is off by {error} px");
    }
    let inference = model.forward_flow(left.clone(), right.clone(), None, 4, Default::default()).unwrap();
    assert!(inference.initial_flow_up.is_none(), "inference does not upsample the start");
    let last = to_vec(inference.flow_up.last().unwrap().clone().neg());
    assert_eq!(last, to_vec(training.iterations[3].clone()), "the training pass changes the iterations");
    model.initial_disparity = InitialDisparity::Zero {};
    assert!(train(&model).initial.is_none());
}

/// Our own safetensors file of an IGEV-Stereo network (what training writes: `model.safetensors`,
/// checkpoints) keeps the pyramid encoders' keys (`feature.*`, `stem_2.*`) and loads back into a
/// fresh network, giving the same disparity bit for bit.
#[test]
fn an_igev_safetensors_file_round_trips() {
    let Some(reference) = golden("an_igev_safetensors_file_round_trips") else { return };
    let golden = SeededGolden::open(&reference);
    let model = golden.model();
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("igev.safetensors");
    checkpoint::save_safetensors(&model, &file, &[]).unwrap();
    let (_, fresh) = model_from_keys(&golden.keys, &default_device()).unwrap();
    let loaded = checkpoint::load_safetensors(fresh, &file).unwrap_or_else(|e| panic!("{e}"));
    let run = |m: &RaftStereo| {
        let out =
            m.forward_flow(golden.tensor("input.left"), golden.tensor("input.right"), None, 2, Default::default());
        to_vec(out.unwrap().flow_up.last().unwrap().clone())
    };
    assert_eq!(run(&model), run(&loaded));
}
