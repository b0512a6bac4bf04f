//! `dgstereo bench --config` with an experiment file of the model zoo: the file's `[model]` is
//! timed (DEFOM-Stereo ViT-S, its monocular network among the stages), and a file that is neither
//! an experiment nor a model configuration is an error naming it.

mod common;

use common::{dgstereo, text};

#[test]
fn bench_times_defom_from_its_experiment_file() {
    let zoo = concat!(env!("CARGO_MANIFEST_DIR"), "/../../experiments/zoo/defom-vits.toml");
    let out = dgstereo(&[
        "bench", "--config", zoo, "--size", "64x96", "--iters", "2", "--runs", "1", "--warmup", "0", "--stages",
    ]);
    let all = text(&out);
    assert!(out.status.success(), "{all}");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let model = stdout.lines().find(|l| l.starts_with("model: ")).unwrap_or_else(|| panic!("{stdout}"));
    assert!(model.contains("DEFOM-Stereo: Depth Anything V2 vits, scale update 8 iterations"), "{model}");
    assert!(model.contains("corr 2 levels x radius 4"), "{model}");
    assert!(stdout.contains("monocular network"), "the stage table times the monocular network:\n{stdout}");

    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, "[encoder]\nwidth = 3\n").unwrap();
    let out = dgstereo(&["bench", "--config", bad.to_str().unwrap(), "--size", "64x64", "--runs", "1"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && !stderr.contains("panicked"), "{}", text(&out));
    assert!(stderr.contains("bad.toml"), "{stderr}");
}
