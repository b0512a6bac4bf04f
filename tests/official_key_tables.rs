//! The official-key tables read both ways: every key of every golden checkpoint (RAFT-Stereo and
//! its realtime model, DEFOM-Stereo, IGEV-Stereo), mapped to our module path and back, is itself;
//! so the loader and the listing of a model's official keys cannot disagree on any of them.

use std::path::Path;

use dgstereo_model::official_keys::{Family, ignored_by_loader, pth_keys};
use dgstereo_model::seeded::golden_state_dict;
use dgstereo_suite::shared_dir_for_test;

/// The keys of a golden file: a `.pth` file's tensors, or a seeded golden's key list.
fn keys_of(path: &Path) -> Vec<String> {
    if path.extension().is_some_and(|e| e == "pth") {
        pth_keys(path).unwrap().into_iter().map(|(k, _)| k).collect()
    } else {
        golden_state_dict(path).unwrap().0.into_iter().map(|t| t.key).collect()
    }
}

#[test]
fn every_golden_key_maps_to_our_path_and_back() {
    let goldens = [
        ("golden/raft_stereo_random.pth", Family::RaftStereo),
        ("golden/raft_stereo_realtime_random.pth", Family::RaftStereo),
        ("golden/defom_stereo_vits_seeded.activations.safetensors", Family::RaftStereo),
        ("golden/igev_stereo_seeded.activations.safetensors", Family::IgevStereo),
    ];
    for (file, family) in goldens {
        let Some(shared) = shared_dir_for_test("every_golden_key_maps_to_our_path_and_back", file) else { return };
        let keys = keys_of(&shared.join(file));
        assert!(keys.len() > 100, "{file}: {} keys", keys.len());
        let mut renamed = 0;
        for key in keys.iter().filter(|k| !ignored_by_loader(k)) {
            let ours = family.module_path_of_official_key(key);
            renamed += usize::from(ours != *key);
            assert_eq!(&family.official_key_of_module_path(&ours), key, "{file}: {key} -> {ours}");
        }
        // Every file has keys whose path differs (`encoder.`), so the tables were applied.
        assert!(renamed > 0, "{file}: no key was renamed");
    }
}
