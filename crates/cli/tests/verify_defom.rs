//! `dgstereo verify defom` on the seeded DEFOM-Stereo golden: it rebuilds the weights from the
//! file's metadata, prints the configuration and one line per recorded tensor, and passes.

mod common;

use common::{assert_verify_passed, assert_verify_refused, verify_on_golden};

#[test]
fn verify_defom_passes_on_the_seeded_golden() {
    let golden = "golden/defom_stereo_vits_seeded.activations.safetensors";
    let Some(out) = verify_on_golden("verify_defom_passes_on_the_seeded_golden", "defom", golden) else { return };
    let stdout = assert_verify_passed(&out, "DEFOM-Stereo", 1e-4);
    let first = stdout.lines().next().unwrap_or_default();
    assert!(first.contains("DEFOM-Stereo: Depth Anything V2 vits"), "{first}");
    assert!(first.contains("6 iterations of which 3 scale iterations"), "{first}");
    let count = |prefix: &str| stdout.lines().filter(|l| l.starts_with(prefix)).count();
    assert_eq!(count("disparity.iter"), 6, "every iteration's disparity:\n{stdout}");
    assert_eq!(count("scale_update_block.call"), 15, "{stdout}");
    assert_eq!(count("update_block.call"), 15, "{stdout}");
    assert_eq!(count("defomencoder."), 12, "{stdout}");
}

#[test]
fn verify_defom_names_a_file_without_seeded_weights() {
    let golden = "golden/raft_stereo_random.activations.safetensors";
    let Some(out) = verify_on_golden("verify_defom_names_a_file_without_seeded_weights", "defom", golden) else {
        return;
    };
    let stderr = assert_verify_refused(&out, "raft_stereo_random.activations.safetensors");
    assert!(stderr.contains("keys"), "{stderr}");
}
