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
    shaped_weights(model).into_iter().map(|(n, _, v)| (n, v)).collect()
}

fn shaped_weights(model: &RaftStereo) -> Vec<(String, Vec<usize>, Vec<f32>)> {
    let mut out: Vec<(String, Vec<usize>, Vec<f32>)> = model
        .collect(None, None, true)
        .into_iter()
        .map(|t| {
            let data = burn::store::bridge::to_data(&t).unwrap();
            let shape = data.shape().to_vec();
            (t.name.clone(), shape, data.convert::<f32>().try_to_vec::<f32>().unwrap())
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
    // Guidance also widens the motion encoder's last convolution (its inputs are the correlation
    // and flow features, then the guidance features): the file's weights on the leading input
    // channels, zeros on the new ones, so it computes what it computed in the baseline.
    parts.model.updater.guidance = GuidanceKind::Gradient;
    let partial = shaped_weights(&Trainer::new(parts.clone(), &device).unwrap().inference_model());
    let donor_shaped = shaped_weights(&donor);
    let mut grown = 0;
    for (name, shape, values) in &partial {
        match donor_shaped.iter().find(|(n, _, _)| n == name) {
            Some((_, _, d)) if d.len() == values.len() => assert_eq!(values, d, "{name} comes from the file"),
            Some((_, ds, d)) => {
                assert!(name.starts_with("update_block.encoder"), "{name} changed shape");
                assert_eq!((ds[0], &ds[2..]), (shape[0], &shape[2..]), "{name}: only the inputs grew");
                let (old, new) = (d.len() / ds[0], values.len() / shape[0]);
                for (o, row) in values.chunks(new).enumerate() {
                    assert_eq!(&row[..old], &d[o * old..(o + 1) * old], "{name}: output {o}, old inputs");
                    assert!(row[old..].iter().all(|v| *v == 0.0), "{name}: output {o}, new inputs start at zero");
                }
                grown += 1;
            }
            None => assert!(
                name.starts_with("fusion") || name.starts_with("update_block.encoder"),
                "{name} is neither in the file nor new"
            ),
        }
    }
    assert!(partial.iter().any(|(n, _, _)| n.starts_with("fusion")));
    assert_eq!(grown, 1, "the motion encoder's last convolution grew");

    // A file that does not exist is named.
    parts.train.init = Some(dir.path().join("missing.safetensors"));
    let e = Trainer::new(parts, &device).err().expect("missing file").to_string();
    assert!(e.contains("missing.safetensors"), "{e}");
}
