//! The bundled default weights (`assets/weights/`) are what the main job uses without
//! `--weights`, and they must keep what training gave them: on the Cones pair the demo must stay
//! clearly below the error of untrained weights (the random reference checkpoint scores EPE
//! 10.58 px, bad-3 84.6 % there; see assets/weights/README.md for the trained figures). With a
//! prior, `infer` picks the paper's default model instead.

mod common;

use common::{assets, dgstereo, infer_cones, text};
use dgstereo_core::shared::shared_dir_for_test;

/// The demo's metric `key` on all pixels with ground truth (its JSON line).
fn demo_metric(stdout: &str, key: &str) -> f64 {
    let line = stdout.lines().find(|l| l.starts_with("all pixels with ground truth:")).expect("metrics line");
    let json: serde_json::Value = serde_json::from_str(line.split_once(':').unwrap().1.trim()).unwrap();
    json[key].as_f64().unwrap()
}

#[test]
fn demo_runs_the_bundled_default_and_it_has_learned() {
    let weights = assets().join("weights/raft-stereo-default.safetensors");
    assert!(weights.is_file(), "the default weights are part of the repository: {}", weights.display());
    let dir = tempfile::tempdir().unwrap();
    let o = dgstereo(&["demo", "--out", dir.path().to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("raft-stereo-default.safetensors"), "{stdout}");
    let (epe, bad2) = (demo_metric(&stdout, "epe"), demo_metric(&stdout, "bad-2"));
    eprintln!("bundled default on Cones, 32 iterations: EPE {epe:.3} px, bad-2 {bad2:.2} %");
    // A quality gate, not the measured value (stage 6: EPE 3.54, bad-3 25.9 %): a broken export
    // or a regression in the network or the loader pushes the errors back towards the untrained
    // 10.6 px and 85 % bad-3; a default older than stage 6 (stage 5: 5.40 px, 33.5 %) fails it too.
    let bad3 = demo_metric(&stdout, "bad-3");
    assert!(epe < 4.5 && bad3 < 30.0, "EPE {epe}, bad-3 {bad3} % on Cones");
    for f in ["cones_disparity.pfm", "cones_disparity_color.png", "cones_side_by_side.png"] {
        assert!(dir.path().join(f).is_file(), "{f}");
    }
}

#[test]
fn infer_with_a_prior_uses_the_paper_default() {
    let Some(shared) = shared_dir_for_test("paper_default", "golden/depth_anything_v2_vits_random.pth") else {
        return;
    };
    let dav2 = shared.join("golden/depth_anything_v2_vits_random.pth");
    let dir = tempfile::tempdir().unwrap();
    let o = infer_cones(&[
        "--prior-weights",
        dav2.to_str().unwrap(),
        "--iters",
        "2",
        "--max-size",
        "128",
        "--out",
        dir.path().to_str().unwrap(),
        "--save",
        "pfm",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("paper-default.safetensors"), "{}", text(&o));
    let written: Vec<String> =
        std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    assert!(written.iter().any(|f| f.ends_with("_disparity.pfm")), "{written:?}");
}
