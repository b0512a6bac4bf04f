//! `train.init`: a run starts from given weights (RAFT-Stereo's `restore_ckpt`), strictly or
//! leaving the parameters the file lacks at their initialisation.

mod common;

use burn::store::ModuleSnapshot;
use dgstereo_core::default_device;
use dgstereo_model::RaftStereo;
use dgstereo_model::checkpoint::save_safetensors;
use dgstereo_model::fusion::FusionConfig;
use dgstereo_model::updater::GuidanceKind;
use dgstereo_prior::{PriorConfig, SimulatedPriorConfig};
use dgstereo_train::Trainer;

fn weights(model: &RaftStereo) -> Vec<(String, Vec<f32>)> {
    let mut out: Vec<(String, Vec<f32>)> = model
        .collect(None, None, true)
        .into_iter()
        .map(|t| {
            let data = burn::store::bridge::to_data(&t).unwrap();
            (t.name.clone(), data.convert::<f32>().try_to_vec::<f32>().unwrap())
        })
        .collect();
    out.sort_by(|a, b| a.0.cmp(&b.0));
    out
}

#[test]
fn a_run_starts_from_the_given_weights() {
    let device = default_device();
    let dir = tempfile::tempdir().unwrap();
    // Weights that differ from the run's own initialisation (another seed).
    let mut donor_parts = common::tiny_parts(1, 1, 1e-3, Some(1), 1);
    donor_parts.train.seed = 99;
    let donor = Trainer::new(donor_parts, &device).unwrap().inference_model();
    let file = dir.path().join("donor.safetensors");
    save_safetensors(&donor, &file, &[]).unwrap();

    let mut parts = common::tiny_parts(1, 1, 1e-3, Some(1), 1);
    let fresh = weights(&Trainer::new(parts.clone(), &device).unwrap().inference_model());
    parts.train.init = Some(file.clone());
    let started = weights(&Trainer::new(parts.clone(), &device).unwrap().inference_model());
    assert_eq!(started, weights(&donor), "every parameter comes from the file");
    assert_ne!(started, fresh);

    // The paper's fusion is not in RAFT-Stereo weights: refused strictly, kept random otherwise.
    parts.model.fusion = FusionConfig::Deformable { features: 8, target: Default::default() };
    parts.prior = PriorConfig::Simulated(SimulatedPriorConfig::default());
    let e = Trainer::new(parts.clone(), &device).err().expect("strict init refuses missing keys").to_string();
    assert!(e.contains("train.init") && e.contains("fusion"), "{e}");
    parts.train.init_strict = false;
    // Guidance also widens the motion encoder's last convolution: another shape, kept random.
    parts.model.updater.guidance = GuidanceKind::Gradient;
    let partial = weights(&Trainer::new(parts.clone(), &device).unwrap().inference_model());
    let donor = weights(&donor);
    for (name, values) in &partial {
        match donor.iter().find(|(n, _)| n == name) {
            Some((_, d)) if d.len() == values.len() => assert_eq!(values, d, "{name} comes from the file"),
            Some(_) => assert!(name.starts_with("update_block.encoder"), "{name} changed shape"),
            None => assert!(
                name.starts_with("fusion") || name.starts_with("update_block.encoder"),
                "{name} is neither in the file nor new"
            ),
        }
    }
    assert!(partial.iter().any(|(n, _)| n.starts_with("fusion")));

    // A file that does not exist is named.
    parts.train.init = Some(dir.path().join("missing.safetensors"));
    let e = Trainer::new(parts, &device).err().expect("missing file").to_string();
    assert!(e.contains("missing.safetensors"), "{e}");
}
