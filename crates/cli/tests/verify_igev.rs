//! `dgstereo verify igev` on the seeded IGEV-Stereo golden: it rebuilds the weights from the
//! file's metadata, prints the configuration and one line per recorded tensor, and passes.

mod common;

use common::{dgstereo, text};
use dgstereo_core::shared::shared_dir_for_test;

#[test]
fn verify_igev_passes_on_the_seeded_golden() {
    let golden = "golden/igev_stereo_seeded.activations.safetensors";
    let Some(shared) = shared_dir_for_test("verify_igev_passes_on_the_seeded_golden", golden) else { return };
    let out = dgstereo(&["verify", "igev", "--reference", shared.join(golden).to_str().unwrap()]);
    let all = text(&out);
    println!("{all}");
    assert!(out.status.success(), "IGEV-Stereo deviates from the reference:\n{all}");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let first = stdout.lines().next().unwrap_or_default();
    assert!(first.contains("IGEV-Stereo: geometry volume max_disp 192"), "{first}");
    assert!(first.contains("4 iterations"), "{first}");
    let count = |prefix: &str| stdout.lines().filter(|l| l.starts_with(prefix)).count();
    assert_eq!(count("disparity."), 5, "the initial and every iteration's disparity:\n{stdout}");
    assert_eq!(count("update_block.call"), 20, "{stdout}");
    assert_eq!(count("feature.call"), 8, "{stdout}");
    assert!(stdout.lines().all(|l| !l.ends_with("FAIL")), "{stdout}");
    let last = stdout.lines().last().unwrap_or_default();
    let error: f32 =
        last.strip_prefix("final flow max abs error: ").unwrap_or_else(|| panic!("{last}")).parse().unwrap();
    assert!(error <= 1e-4, "{last}");
}

#[test]
fn verify_igev_names_a_file_of_another_model() {
    let golden = "golden/defom_stereo_vits_seeded.activations.safetensors";
    let Some(shared) = shared_dir_for_test("verify_igev_names_a_file_of_another_model", golden) else { return };
    let out = dgstereo(&["verify", "igev", "--reference", shared.join(golden).to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{}", text(&out));
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(stderr.contains("defom_stereo_vits_seeded.activations.safetensors"), "{stderr}");
}
