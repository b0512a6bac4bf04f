//! `dgstereo verify defom` on the seeded DEFOM-Stereo golden: it rebuilds the weights from the
//! file's metadata, prints the configuration and one line per recorded tensor, and passes.

mod common;

use common::{dgstereo, text};
use dgstereo_core::shared::shared_dir_for_test;

#[test]
fn verify_defom_passes_on_the_seeded_golden() {
    let golden = "golden/defom_stereo_vits_seeded.activations.safetensors";
    let Some(shared) = shared_dir_for_test("verify_defom_passes_on_the_seeded_golden", golden) else { return };
    let out = dgstereo(&["verify", "defom", "--reference", shared.join(golden).to_str().unwrap()]);
    let all = text(&out);
    println!("{all}");
    assert!(out.status.success(), "DEFOM-Stereo deviates from the reference:\n{all}");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let first = stdout.lines().next().unwrap_or_default();
    assert!(first.contains("DEFOM-Stereo: Depth Anything V2 vits"), "{first}");
    assert!(first.contains("6 iterations of which 3 scale iterations"), "{first}");
    let count = |prefix: &str| stdout.lines().filter(|l| l.starts_with(prefix)).count();
    assert_eq!(count("disparity.iter"), 6, "every iteration's disparity:\n{stdout}");
    assert_eq!(count("scale_update_block.call"), 15, "{stdout}");
    assert_eq!(count("update_block.call"), 15, "{stdout}");
    assert_eq!(count("defomencoder."), 12, "{stdout}");
    assert!(stdout.lines().all(|l| !l.ends_with("FAIL")), "{stdout}");
    let last = stdout.lines().last().unwrap_or_default();
    let error: f32 =
        last.strip_prefix("final flow max abs error: ").unwrap_or_else(|| panic!("{last}")).parse().unwrap();
    assert!(error <= 1e-4, "{last}");
}

#[test]
fn verify_defom_names_a_file_without_seeded_weights() {
    let golden = "golden/raft_stereo_random.activations.safetensors";
    let Some(shared) = shared_dir_for_test("verify_defom_names_a_file_without_seeded_weights", golden) else { return };
    let out = dgstereo(&["verify", "defom", "--reference", shared.join(golden).to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{}", text(&out));
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(stderr.contains("raft_stereo_random.activations.safetensors"), "{stderr}");
    assert!(stderr.contains("keys"), "{stderr}");
}
