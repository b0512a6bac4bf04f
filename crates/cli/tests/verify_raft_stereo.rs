//! `dgstereo verify raft-stereo` on both golden checkpoints, and `dgstereo infer` with an
//! official `.pth` whose architecture is not the default: the configuration comes from the
//! checkpoint's tensors, is printed, and its official preset's iterations are used.

mod common;

use common::{dgstereo, infer_cones, text};
use dgstereo_core::shared::shared_dir_for_test;

/// Runs `verify raft-stereo` on `golden/{name}.pth` against its activations; returns stdout.
fn verify(test: &str, name: &str) -> Option<String> {
    let weights = format!("golden/{name}.pth");
    let shared = shared_dir_for_test(test, &weights)?;
    let reference = shared.join(format!("golden/{name}.activations.safetensors"));
    let out = dgstereo(&[
        "verify",
        "raft-stereo",
        "--weights",
        shared.join(&weights).to_str().unwrap(),
        "--reference",
        reference.to_str().unwrap(),
    ]);
    let all = text(&out);
    println!("{all}");
    assert!(out.status.success(), "{name} deviates from the reference:\n{all}");
    Some(String::from_utf8_lossy(&out.stdout).into_owned())
}

/// The error of the `final flow max abs error: X` line, which must come last.
fn final_error(stdout: &str) -> f32 {
    let last = stdout.lines().last().unwrap_or_default();
    let value = last.strip_prefix("final flow max abs error: ").unwrap_or_else(|| panic!("last line: {last}"));
    value.parse().unwrap_or_else(|e| panic!("{value}: {e}"))
}

#[test]
fn verify_passes_on_the_realtime_golden() {
    let Some(stdout) = verify("verify_passes_on_the_realtime_golden", "raft_stereo_realtime_random") else { return };
    assert!(stdout.lines().next().unwrap_or_default().contains("shared backbone, n_downsample 3, 2 GRU levels"));
    let count = |prefix: &str| stdout.lines().filter(|l| l.starts_with(prefix)).count();
    assert_eq!(count("iter."), 7, "every iteration's upsampled flow:\n{stdout}");
    for key in
        ["fmap.left ", "fmap.right ", "context.hidden.0 ", "context.hidden.1 ", "final.flow_up ", "final.flow_lowres "]
    {
        assert_eq!(count(key), 1, "{key}:\n{stdout}");
    }
    assert!(stdout.lines().all(|l| !l.ends_with("FAIL")), "{stdout}");
    assert!(final_error(&stdout) <= 1e-3);
}

#[test]
fn verify_passes_on_the_default_golden() {
    let Some(stdout) = verify("verify_passes_on_the_default_golden", "raft_stereo_random") else { return };
    assert!(
        stdout.lines().next().unwrap_or_default().contains("separate feature encoder, n_downsample 2, 3 GRU levels")
    );
    assert!(final_error(&stdout) <= 1e-3);
}

#[test]
fn infer_reads_the_realtime_architecture_from_the_checkpoint() {
    let weights = "golden/raft_stereo_realtime_random.pth";
    let Some(shared) = shared_dir_for_test("infer_reads_the_realtime_architecture_from_the_checkpoint", weights) else {
        return;
    };
    let out_dir = std::env::temp_dir().join(format!("dgstereo-infer-realtime-{}", std::process::id()));
    let out = infer_cones(&[
        "--weights",
        shared.join(weights).to_str().unwrap(),
        "--max-size",
        "128",
        "--save",
        "pfm",
        "--out",
        out_dir.to_str().unwrap(),
    ]);
    let all = text(&out);
    assert!(out.status.success(), "{all}");
    let stderr = String::from_utf8_lossy(&out.stderr);
    let line = stderr.lines().find(|l| l.starts_with("configuration: ")).unwrap_or_else(|| panic!("{stderr}"));
    assert!(line.contains("shared backbone, n_downsample 3, 2 GRU levels"), "{line}");
    assert!(line.contains("slow_fast_gru on, 7 iterations"), "{line}");
    assert!(line.contains("preset: realtime"), "{line}");
    let written: Vec<String> = std::fs::read_dir(&out_dir)
        .map(|d| d.filter_map(|e| e.ok()).map(|e| e.file_name().to_string_lossy().into_owned()).collect())
        .unwrap_or_default();
    assert!(written.iter().any(|f| f.ends_with("_disparity.pfm")), "{written:?}\n{all}");

    // Flags override the preset.
    let out = infer_cones(&[
        "--weights",
        shared.join(weights).to_str().unwrap(),
        "--max-size",
        "64",
        "--iters",
        "2",
        "--slow-fast-gru",
        "false",
        "--save",
        "pfm",
        "--out",
        out_dir.to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{}", text(&out));
    assert!(stderr.contains("slow_fast_gru off, 2 iterations"), "{stderr}");
    let _ = std::fs::remove_dir_all(&out_dir);
}

#[test]
fn an_experiment_that_does_not_fit_the_checkpoint_names_its_architecture() {
    let weights = "golden/raft_stereo_realtime_random.pth";
    let Some(shared) = shared_dir_for_test("an_experiment_that_does_not_fit_the_checkpoint", weights) else { return };
    let tmp = tempfile::tempdir().unwrap();
    let experiment = tmp.path().join("default.toml");
    std::fs::write(&experiment, "[model.updater]\nn_gru_layers = 3\n").unwrap();
    let out = infer_cones(&[
        "--weights",
        shared.join(weights).to_str().unwrap(),
        "--experiment",
        experiment.to_str().unwrap(),
        "--out",
        tmp.path().join("out").to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{}", text(&out));
    assert!(!stderr.contains("panicked"), "{stderr}");
    let line = stderr.lines().find(|l| l.starts_with("error: ")).unwrap_or_else(|| panic!("{stderr}"));
    assert!(line.contains("raft_stereo_realtime_random.pth"), "{line}");
    assert!(line.contains("the checkpoint's tensors show: shared backbone, n_downsample 3, 2 GRU levels"), "{line}");
}
