//! `dgstereo verify igev` on the seeded IGEV-Stereo golden: it rebuilds the weights from the
//! file's metadata, prints the configuration and one line per recorded tensor, and passes.

mod common;

use common::{assert_verify_passed, assert_verify_refused, verify_on_golden};

#[test]
fn verify_igev_passes_on_the_seeded_golden() {
    let golden = "golden/igev_stereo_seeded.activations.safetensors";
    let Some(out) = verify_on_golden("verify_igev_passes_on_the_seeded_golden", "igev", golden) else { return };
    let stdout = assert_verify_passed(&out, "IGEV-Stereo", 1e-4);
    let first = stdout.lines().next().unwrap_or_default();
    assert!(first.contains("IGEV-Stereo: geometry volume max_disp 192"), "{first}");
    assert!(first.contains("4 iterations"), "{first}");
    let count = |prefix: &str| stdout.lines().filter(|l| l.starts_with(prefix)).count();
    assert_eq!(count("disparity."), 5, "the initial and every iteration's disparity:\n{stdout}");
    assert_eq!(count("update_block.call"), 20, "{stdout}");
    assert_eq!(count("feature.call"), 8, "{stdout}");
}

#[test]
fn verify_igev_names_a_file_of_another_model() {
    let golden = "golden/defom_stereo_vits_seeded.activations.safetensors";
    let Some(out) = verify_on_golden("verify_igev_names_a_file_of_another_model", "igev", golden) else { return };
    assert_verify_refused(&out, "defom_stereo_vits_seeded.activations.safetensors");
}
