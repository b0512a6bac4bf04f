//! `dgstereo bench` times a checkpoint (`--weights`) and takes the model card beside the shipped
//! weights as `--config`; `dgstereo export onnx` exports the bundled default at 64x64 (the
//! narrowest widths pool its correlation pyramid below one column) and names prior maps only for
//! a model that takes them.

mod common;

use common::{assets, dgstereo, text};

fn bench(extra: &[&str]) -> std::process::Output {
    let mut args = vec!["bench", "--size", "72x72", "--iters", "1", "--runs", "1", "--warmup", "0"];
    args.extend_from_slice(extra);
    dgstereo(&args)
}

#[test]
fn bench_times_shipped_weights_and_takes_their_model_card() {
    let weights = assets().join("weights/raft-stereo-default.safetensors");
    let card = assets().join("weights/raft-stereo-default.toml");
    // RAFT-Stereo's default pads 72 to 96; the bundled default (n_downsample 3) to 128.
    let o = bench(&[]);
    assert!(o.status.success() && text(&o).contains("(padded 96x96)"), "{}", text(&o));
    let o = bench(&["--weights", weights.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        text(&o).contains("raft-stereo-default.safetensors") && text(&o).contains("(padded 128x128)"),
        "{}",
        text(&o)
    );
    let o = bench(&["--config", card.to_str().unwrap()]);
    assert!(o.status.success() && text(&o).contains("(padded 128x128)"), "{}", text(&o));
    // A file that is neither is named.
    let tmp = tempfile::tempdir().unwrap();
    let bad = tmp.path().join("bad.toml");
    std::fs::write(&bad, "colour = \"blue\"\n").unwrap();
    let o = bench(&["--config", bad.to_str().unwrap()]);
    assert!(!o.status.success() && text(&o).contains("bad.toml"), "{}", text(&o));
    let o = bench(&["--weights", tmp.path().join("missing.safetensors").to_str().unwrap()]);
    assert!(!o.status.success() && text(&o).contains("missing.safetensors"), "{}", text(&o));
}

#[test]
fn export_of_the_bundled_default_at_64x64_and_the_inputs_it_names() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("default.onnx");
    let o = dgstereo(&["export", "onnx", "--size", "64x64", "--iters", "1", "-o", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(!text(&o).contains("panicked") && out.is_file(), "{}", text(&o));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("disparity 1x1x64x64"), "{stdout}");
    assert!(stdout.contains("inputs: left 1x3x64x64, right 1x3x64x64 (float32, RGB 0..255)"), "{stdout}");
    assert!(!stdout.contains("prior"), "a model without a prior takes no prior maps: {stdout}");
    let paper = assets().join("weights/paper-default.safetensors");
    let out = tmp.path().join("paper.onnx");
    let args = ["export", "onnx", "--weights", paper.to_str().unwrap(), "--size", "64x64", "--iters", "1", "-o"];
    let o = dgstereo(&[&args[..], &[out.to_str().unwrap()]].concat());
    assert!(o.status.success(), "{}", text(&o));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        stdout.contains("left_prior 1x1x64x64") && stdout.contains("prior maps: relative inverse depth"),
        "{stdout}"
    );
    // Under the minimum: an error naming the size, and no file.
    let small = tmp.path().join("small.onnx");
    let o = dgstereo(&["export", "onnx", "--size", "16x64", "--iters", "1", "-o", small.to_str().unwrap()]);
    assert!(!o.status.success() && text(&o).contains("16x64") && !small.exists(), "{}", text(&o));
}
