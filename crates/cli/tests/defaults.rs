//! The bundled default weights (`assets/weights/`) are what the main job uses without
//! `--weights`, and they must keep what training gave them: on the Cones pair the demo must stay
//! clearly below the error of untrained weights (the random reference checkpoint scores EPE
//! 10.58 px, bad-3 84.6 % there; see assets/weights/README.md for the trained figures). With a
//! prior, `infer` picks the paper's default model instead.

mod common;

use common::{assets, cones_dir, dgstereo, infer_cones, text};
use dgstereo_core::shared::shared_dir_for_test;

/// The demo's metric `key` on all pixels with ground truth (its JSON line).
fn demo_metric(stdout: &str, key: &str) -> f64 {
    let line = stdout.lines().find(|l| l.starts_with("all pixels with ground truth:")).expect("metrics line");
    let json: serde_json::Value = serde_json::from_str(line.split_once(':').unwrap().1.trim()).unwrap();
    json[key].as_f64().unwrap()
}

/// The golden Depth Anything V2 (ViT-S, random weights) checkpoint in the shared data, or `None`
/// (with the printed notice) where the shared data is missing outside CI.
fn golden_depth_anything(test: &str) -> Option<std::path::PathBuf> {
    const FILE: &str = "golden/depth_anything_v2_vits_random.pth";
    shared_dir_for_test(test, FILE).map(|shared| shared.join(FILE))
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
    // A quality gate, not the measured value (stage 17, run at 900x750 by `--min-size auto`: EPE
    // 1.36, bad-3 10.3 %): a broken export or a regression in the network or the loader pushes
    // the errors back towards the untrained 10.6 px and 85 % bad-3; the previous default
    // (stage 16: 1.49 px, 11.7 %) fails it too.
    assert!(stdout.contains("(network 900x750)"), "{stdout}");
    let bad3 = demo_metric(&stdout, "bad-3");
    assert!(epe < 1.43 && bad3 < 11.0, "EPE {epe}, bad-3 {bad3} % on Cones");
    for f in ["cones_disparity.pfm", "cones_disparity_color.png", "cones_side_by_side.png"] {
        assert!(dir.path().join(f).is_file(), "{f}");
    }
}

#[test]
fn infer_with_a_prior_uses_the_paper_default() {
    let Some(dav2) = golden_depth_anything("paper_default") else { return };
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
    assert!(text(&o).contains("(depth prior "), "the pair's line says how long its prior took: {}", text(&o));
    let written: Vec<String> =
        std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    assert!(written.iter().any(|f| f.ends_with("_disparity.pfm")), "{written:?}");
}

/// `bench --prior-weights` times the depth prior inside every run of a model that uses one, and
/// refuses a model that does not and a half precision (the prior runs in f32, as in `infer`).
#[test]
fn bench_times_the_depth_prior_of_a_model_with_one() {
    let Some(dav2) = golden_depth_anything("bench_prior") else { return };
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("paper.toml");
    std::fs::write(&config, "[updater]\nguidance = \"gradient\"\n\n[fusion]\nkind = \"deformable\"\n").unwrap();
    let bench = |extra: &[&str]| {
        let mut args = vec!["bench", "--size", "64x64", "--iters", "1", "--runs", "1", "--warmup", "0"];
        args.extend_from_slice(extra);
        dgstereo(&args)
    };
    let o = bench(&["--config", config.to_str().unwrap(), "--prior-weights", dav2.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("of which the depth prior (Depth Anything V2, both views): median"), "{}", text(&o));
    let o = bench(&["--prior-weights", dav2.to_str().unwrap()]);
    assert!(!o.status.success() && text(&o).contains("uses no depth prior"), "{}", text(&o));
    let half = ["--config", config.to_str().unwrap(), "--prior-weights", dav2.to_str().unwrap(), "--precision", "f16"];
    let o = bench(&half);
    assert!(!o.status.success() && text(&o).contains("runs in f32 only"), "{}", text(&o));
}

#[test]
fn small_pairs_are_upscaled_for_the_eighth_resolution_default() {
    use dgstereo_data::resize::resize_rgb;
    use dgstereo_data::{load_rgb, read_disparity, save_rgb};
    // Cones at a third of its size (150x125). The bundled default works at 1/8 resolution, so
    // `--min-size auto` runs it at 900x750, `300` at 300x250 and `off` at the given size; the
    // disparity always comes back at 150x125 and at the input's scale.
    let dir = tempfile::tempdir().unwrap();
    let cones = assets().join("cones");
    for side in ["left", "right"] {
        let img = load_rgb(cones.join(format!("{side}_rgb.png"))).unwrap();
        save_rgb(dir.path().join(format!("small_{side}.png")), &resize_rgb(&img, 1.0 / 3.0, 1.0 / 3.0)).unwrap();
    }
    let (l, r) = (dir.path().join("small_left.png"), dir.path().join("small_right.png"));
    let pair = ["infer", "-l", l.to_str().unwrap(), "-r", r.to_str().unwrap()];
    let mut medians = Vec::new();
    for (min_size, network) in [("auto", "900x750"), ("300", "300x250"), ("off", "150x125")] {
        let out = dir.path().join(min_size);
        let args = ["--iters", "4", "--save", "pfm", "--min-size", min_size, "--out", out.to_str().unwrap()];
        let o = dgstereo(&[&pair[..], &args[..]].concat());
        assert!(o.status.success(), "{}", text(&o));
        assert!(text(&o).contains(&format!("150x125 (network {network},")), "{}", text(&o));
        let d = read_disparity(out.join("small_disparity.pfm")).unwrap();
        assert_eq!((d.width, d.height), (150, 125));
        let mut v: Vec<f32> = d.data.iter().copied().filter(|x| x.is_finite()).collect();
        v.sort_by(f32::total_cmp);
        medians.push(v[v.len() / 2]);
    }
    // Cones' true disparities at this size are ~5-18 px. Without the rescaling a 2x run would
    // read about twice the native median and a 6x run six times.
    let native = medians[2];
    assert!(native > 2.0, "native median disparity {native}");
    for m in &medians[..2] {
        assert!((0.6..1.6).contains(&(m / native)), "medians {medians:?}");
    }
    // A lower bound above the cap is refused before any work, naming both.
    let o = dgstereo(&[&pair[..], &["--min-size", "300", "--max-size", "200"]].concat());
    assert!(!o.status.success());
    assert!(text(&o).contains("--min-size: 300 is larger than --max-size 200"), "{}", text(&o));
}

#[test]
fn the_left_right_check_fills_what_the_right_view_cannot_see() {
    use dgstereo_data::{load_mask, read_disparity};
    use dgstereo_eval::{ValidOptions, evaluate};
    // Cones at its bundled size, run at that size (cheap) with and without `--lr-check`. Its
    // nearest-to-the-left surface is ~16 px away, so the band of columns 0-15 has no match in
    // the right view: the check must reject most of it, fill only what it rejects, and lower the
    // error against the ground truth.
    let dir = tempfile::tempdir().unwrap();
    let run = |extra: &[&str], out: &str| {
        let out = dir.path().join(out);
        let args = [&["--iters", "8", "--min-size", "off", "--out", out.to_str().unwrap()], extra].concat();
        let o = infer_cones(&args);
        assert!(o.status.success(), "{}", text(&o));
        (o, out)
    };
    let (_, plain) = run(&["--save", "pfm"], "plain");
    let (o, checked) = run(&["--save", "pfm,rejected", "--lr-check"], "checked");
    assert!(text(&o).contains("left-right check replaced"), "{}", text(&o));
    let before = read_disparity(plain.join("rgb_disparity.pfm")).unwrap();
    let after = read_disparity(checked.join("rgb_disparity.pfm")).unwrap();
    let rejected = load_mask(checked.join("rgb_rejected.png")).unwrap();
    assert_eq!((rejected.width, rejected.height), (450, 375));
    let share = |cols: std::ops::Range<usize>| {
        let n = (0..375).flat_map(|y| cols.clone().map(move |x| y * 450 + x)).filter(|&i| rejected.data[i]).count();
        n as f64 / (375 * cols.len()) as f64
    };
    let (band, rest) = (share(0..12), share(12..450));
    assert!(band > 0.8 && rest < 0.35, "rejected: {band:.2} of the band, {rest:.2} elsewhere");
    for i in 0..after.data.len() {
        if !rejected.data[i] {
            assert_eq!(after.data[i], before.data[i], "pixel {i} was accepted but changed");
        }
    }
    let gt = read_disparity(cones_dir().join("disp_left.pfm")).unwrap();
    let epe = |d| evaluate(d, &gt, None, ValidOptions { max_disp: None }).unwrap().epe;
    let (e0, e1) = (epe(&before), epe(&after));
    eprintln!(
        "Cones 450x375, 8 iterations: EPE {e0:.3} -> {e1:.3} px with the check; rejected {band:.2} of the band, {rest:.2} elsewhere"
    );
    assert!(e1 < e0, "EPE {e0} -> {e1}");
    // Wrong uses are refused before any pair runs.
    for (args, message) in [
        (&["--save", "rejected"][..], "--save rejected writes the pixels the left-right check replaced"),
        (&["--lr-check", "0"][..], "--lr-check: 0: the threshold must be a positive number"),
    ] {
        let o = infer_cones(args);
        assert!(!o.status.success());
        assert!(text(&o).contains(message), "{}", text(&o));
    }
}

#[test]
fn half_precision_inference_loads_f32_weights_and_agrees_with_f32() {
    use dgstereo_data::read_disparity;
    // The bundled weights are stored in f32; `--precision f16` must cast them after loading (the
    // backends do not mix f32 weights with f16 activations) and give nearly the f32 map: f16
    // rounds a 30 px disparity to ~0.015 px.
    let dir = tempfile::tempdir().unwrap();
    let mut maps = Vec::new();
    for precision in ["f32", "f16"] {
        let out = dir.path().join(precision);
        let args = ["--iters", "4", "--min-size", "off", "--save", "pfm", "--precision", precision];
        let o = infer_cones(&[&args[..], &["--out", out.to_str().unwrap()]].concat());
        assert!(o.status.success(), "{}", text(&o));
        maps.push(read_disparity(out.join("rgb_disparity.pfm")).unwrap());
    }
    let n = maps[0].data.len() as f64;
    let diffs: Vec<f64> = maps[0].data.iter().zip(&maps[1].data).map(|(a, b)| (a - b).abs() as f64).collect();
    let mean = diffs.iter().sum::<f64>() / n;
    let mean_disparity = maps[0].data.iter().map(|&v| v as f64).sum::<f64>() / n;
    assert!(mean_disparity > 10.0, "the f32 map is not a Cones disparity: mean {mean_disparity}");
    assert!(mean > 0.0 && mean < 0.1, "mean |f16 - f32| = {mean} px");
    // Half precision with a depth prior is refused before anything loads.
    let o = infer_cones(&["--precision", "f16", "--prior", "file:."]);
    assert!(!o.status.success());
    assert!(text(&o).contains("the depth prior runs in f32 only"), "{}", text(&o));
}
