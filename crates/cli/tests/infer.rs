//! `dgstereo infer` and `dgstereo eval` run as a user runs them: the binary on the OAK-D grayscale
//! pairs and the Cones pair, every `--save` kind written and read back, and bad inputs reported.
//!
//! Compute is kept small: one update iteration and images downscaled by `--max-size` (the
//! disparity is still written at the input size), with the reference random weights.

mod common;

use std::path::{Path, PathBuf};
use std::process::Output;

use common::{cones_dir, dgstereo, infer_cones};
use dgstereo_core::shared::shared_dir_for_test;
use dgstereo_data::{DisparityMap, load_rgb, read_disparity, save_rgb};

fn weights(test: &str) -> Option<PathBuf> {
    shared_dir_for_test(test, "golden/raft_stereo_random.pth").map(|s| s.join("golden/raft_stereo_random.pth"))
}

fn text(o: &Output) -> (String, String) {
    (String::from_utf8_lossy(&o.stdout).into_owned(), String::from_utf8_lossy(&o.stderr).into_owned())
}

fn assert_no_panic(o: &Output) {
    let (out, err) = text(o);
    assert!(!out.contains("panicked") && !err.contains("panicked") && !err.contains("RUST_BACKTRACE"), "{out}\n{err}");
}

/// The vertex count of a PLY header, and the bytes (binary) or lines (ascii) after it.
fn read_ply(path: &Path) -> (usize, Vec<u8>) {
    let bytes = std::fs::read(path).unwrap();
    let end = bytes.windows(11).position(|w| w == b"end_header\n").expect("PLY header ends") + 11;
    let header = std::str::from_utf8(&bytes[..end]).unwrap();
    assert!(header.starts_with("ply\n"), "{header}");
    let count =
        header.lines().find_map(|l| l.strip_prefix("element vertex ")).expect("a vertex element").parse().unwrap();
    (count, bytes[end..].to_vec())
}

/// Checks every kind written for pair `name` against the PFM disparity; returns the disparity.
fn check_outputs(out: &Path, name: &str, size: (usize, usize), max_depth: f32, ply_binary: bool) -> DisparityMap {
    let disp = read_disparity(out.join(format!("{name}_disparity.pfm"))).unwrap();
    assert_eq!((disp.width, disp.height), size, "disparity at the input size");
    assert!(disp.data.iter().all(|d| d.is_finite()));
    let npy = read_disparity(out.join(format!("{name}_disparity.npy"))).unwrap();
    assert_eq!(npy, disp);
    let png = read_disparity(out.join(format!("{name}_disparity_png16.png"))).unwrap();
    for (p, d) in png.data.iter().zip(&disp.data) {
        if *d > 0.0 && *d < 255.0 {
            assert!((p - d).abs() <= 1.0 / 256.0, "png16 {p} vs {d}");
        } else if *d <= 0.0 {
            assert_eq!(*p, 0.0);
        }
    }
    let color = load_rgb(out.join(format!("{name}_disparity_color.png"))).unwrap();
    assert_eq!(color.width, size.0);
    assert!(color.height > size.1, "a legend below the map");
    let preview = load_rgb(out.join(format!("{name}_preview.png"))).unwrap();
    assert_eq!((preview.width, preview.height), (2 * size.0, size.1), "left image | colour map");
    let depth = read_disparity(out.join(format!("{name}_depth.pfm"))).unwrap();
    assert_eq!((depth.width, depth.height), size);
    let kept = depth.data.iter().filter(|z| z.is_finite() && **z > 0.0 && **z <= max_depth).count();
    let ply = out.join(format!("{name}_points.ply"));
    let (count, body) = read_ply(&ply);
    assert_eq!(count, kept, "{}: one point per pixel with a valid, near depth", ply.display());
    if ply_binary {
        assert_eq!(body.len(), 15 * count);
        for point in body.chunks(15) {
            let z = f32::from_le_bytes(point[8..12].try_into().unwrap());
            assert!(z > 0.0 && z <= max_depth);
        }
    } else {
        let lines: Vec<&str> = std::str::from_utf8(&body).unwrap().lines().collect();
        assert_eq!(lines.len(), count);
        for l in lines {
            let v: Vec<f64> = l.split(' ').map(|t| t.parse().unwrap()).collect();
            assert_eq!(v.len(), 6);
            assert!(v[2] > 0.0 && v[2] <= max_depth as f64 + 1e-3);
        }
    }
    disp
}

#[test]
fn oakd_grayscale_pairs_write_every_kind() {
    let (Some(w), Some(shared)) = (weights("oakd"), shared_dir_for_test("oakd", "data/oakd-pairs")) else { return };
    let data = shared.join("data/oakd-pairs");
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    let calib = data.join("stereodemo_calibration.json");
    let o = dgstereo(&[
        "infer",
        "-l",
        &format!("{}/*_left.png", data.display()),
        "-r",
        &format!("{}/*_right.png", data.display()),
        "--save",
        "pfm,npy,png16,color,preview,depth,ply",
        "--calib",
        calib.to_str().unwrap(),
        "--max-depth",
        "1000",
        "--iters",
        "1",
        "--max-size",
        "96",
        "--weights",
        w.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_no_panic(&o);
    let (stdout, stderr) = text(&o);
    assert!(o.status.success(), "{stdout}\n{stderr}");
    assert!(stdout.contains("3 of 3 pair(s) done"), "{stdout}");
    // fx = 451.03, baseline 0.075 m, cx1 = cx0: depth = 33.83 / d.
    let fb = 451.0344543457031_f64 * 0.075;
    for name in ["corridor", "desk", "stairs"] {
        let disp = check_outputs(&out, name, (640, 480), 1000.0, true);
        let depth = read_disparity(out.join(format!("{name}_depth.pfm"))).unwrap();
        for (z, d) in depth.data.iter().zip(&disp.data).step_by(997) {
            if *d > 0.0 {
                assert!((*z as f64 - fb / *d as f64).abs() <= 1e-4 * *z as f64, "depth {z} for disparity {d}");
            } else {
                assert!(z.is_infinite());
            }
        }
    }
}

#[test]
fn cones_pair_with_middlebury_calibration_and_ascii_ply() {
    let Some(w) = weights("cones") else { return };
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("out");
    // Middlebury calib.txt of a full-size (4x) capture: the intrinsics are scaled to 450x375.
    let calib = tmp.path().join("calib.txt");
    std::fs::write(
        &calib,
        "cam0=[3000 0 900; 0 3000 750; 0 0 1]\ncam1=[3000 0 900; 0 3000 750; 0 0 1]\ndoffs=0\nbaseline=100\nwidth=1800\nheight=1500\nndisp=256\n",
    )
    .unwrap();
    let o = infer_cones(&[
        "--save",
        "pfm,npy,png16,color,preview,depth,ply",
        "--calib",
        calib.to_str().unwrap(),
        "--max-depth",
        "1000",
        "--ply-encoding",
        "ascii",
        "--iters",
        "1",
        "--max-size",
        "64",
        "--weights",
        w.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_no_panic(&o);
    let (stdout, stderr) = text(&o);
    assert!(o.status.success(), "{stdout}\n{stderr}");
    let disp = check_outputs(&out, "rgb", (450, 375), 1000.0, false);
    // fx scaled to 750 px, baseline 0.1 m: depth = 75 / d.
    let depth = read_disparity(out.join("rgb_depth.pfm")).unwrap();
    let i = disp.data.iter().position(|d| *d > 0.0).expect("some positive disparity");
    assert!((depth.data[i] - 75.0 / disp.data[i]).abs() <= 1e-4 * depth.data[i]);
}

#[test]
fn bad_pairs_are_reported_and_the_others_processed() {
    let Some(w) = weights("bad_pairs") else { return };
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("pairs");
    std::fs::create_dir(&dir).unwrap();
    let cones = cones_dir();
    let (left, right) = (cones.join("left_rgb.png"), cones.join("right_rgb.png"));
    std::fs::copy(&left, dir.join("good_left.png")).unwrap();
    std::fs::copy(&right, dir.join("good_right.png")).unwrap();
    std::fs::copy(&left, dir.join("mismatch_left.png")).unwrap();
    save_rgb(dir.join("mismatch_right.png"), &dgstereo_data::RgbImage::new(40, 30)).unwrap();
    let bytes = std::fs::read(&left).unwrap();
    std::fs::write(dir.join("truncated_left.png"), &bytes[..bytes.len() / 3]).unwrap();
    std::fs::copy(&right, dir.join("truncated_right.png")).unwrap();
    std::fs::copy(&left, dir.join("lonely_left.png")).unwrap();
    let out = tmp.path().join("out");
    let o = dgstereo(&[
        "infer",
        "--pairs",
        dir.to_str().unwrap(),
        "--iters",
        "1",
        "--max-size",
        "64",
        "--weights",
        w.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_no_panic(&o);
    let (stdout, stderr) = text(&o);
    assert!(!o.status.success(), "bad pairs make the exit status non-zero\n{stdout}\n{stderr}");
    assert!(out.join("good_disparity.pfm").is_file() && out.join("good_disparity_color.png").is_file());
    assert!(!out.join("mismatch_disparity.pfm").exists() && !out.join("truncated_disparity.pfm").exists());
    assert!(stdout.contains("1 of 4 pair(s) done, 3 failed"), "{stdout}");
    let error_line = |file: &str| {
        stderr
            .lines()
            .find(|l| l.starts_with("error: ") && l.contains(file))
            .unwrap_or_else(|| panic!("no error line naming {file}:\n{stderr}"))
            .to_string()
    };
    assert!(error_line("mismatch_left.png").contains("40x30"));
    assert!(error_line("lonely_left.png").contains("missing right image"));
    let truncated = error_line("truncated_left.png");
    assert!(!truncated.contains("good_"), "{truncated}");
    // The failures are listed again at the end.
    let listed = stderr.split("failed:").nth(1).expect("a list of failures");
    for f in ["mismatch_left.png", "truncated_left.png", "lonely_left.png"] {
        assert!(listed.contains(f), "{listed}");
    }
}

#[test]
fn whole_run_problems_fail_before_any_pair() {
    let Some(w) = weights("whole_run") else { return };
    let tmp = tempfile::tempdir().unwrap();
    let cones = cones_dir();
    let (l, r) = (cones.join("left_rgb.png"), cones.join("right_rgb.png"));
    let bad_calib = tmp.path().join("broken.json");
    std::fs::write(&bad_calib, "{\"fx\": 450, \"cy\": 3").unwrap();
    let experiment = tmp.path().join("small.toml");
    std::fs::write(&experiment, "[model.updater]\nhidden_dims = [32, 32, 32]\n").unwrap();
    let out = tmp.path().join("out");
    let base = ["infer", "-l", l.to_str().unwrap(), "-r", r.to_str().unwrap(), "--out", out.to_str().unwrap()];
    let cases: [(Vec<&str>, &str); 4] = [
        // No calibration for depth output: refused before the model loads, naming the pair.
        (vec!["--save", "depth", "--weights", "/nonexistent/weights.pth"], "left_rgb.png"),
        (
            vec!["--save", "depth", "--calib", bad_calib.to_str().unwrap(), "--weights", w.to_str().unwrap()],
            "broken.json",
        ),
        (
            vec!["--experiment", experiment.to_str().unwrap(), "--weights", w.to_str().unwrap()],
            "raft_stereo_random.pth",
        ),
        (vec!["--weights", "/nonexistent/weights.pth"], "/nonexistent/weights.pth"),
    ];
    for (extra, needle) in cases {
        let args: Vec<&str> = base.iter().copied().chain(extra).collect();
        let o = dgstereo(&args);
        assert_no_panic(&o);
        let (stdout, stderr) = text(&o);
        assert!(!o.status.success(), "{args:?}\n{stdout}\n{stderr}");
        let line = stderr.lines().find(|l| l.starts_with("error: ")).unwrap_or_else(|| panic!("{stderr}"));
        assert!(line.contains(needle), "{line}");
        assert!(!out.join("rgb_disparity.pfm").exists());
    }
}

#[test]
fn eval_scores_the_cones_fixture_and_writes_csv_and_json() {
    let Some(w) = weights("eval_cones") else { return };
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("eval");
    let o = dgstereo(&[
        "eval",
        "--dataset",
        "folder",
        "--root",
        cones_dir().to_str().unwrap(),
        "--iters",
        "1",
        "--max-size",
        "64",
        "--weights",
        w.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_no_panic(&o);
    let (stdout, stderr) = text(&o);
    assert!(o.status.success(), "{stdout}\n{stderr}");
    assert!(stdout.contains("protocol: generic"), "{stdout}");
    let csv = std::fs::read_to_string(out.join("eval.csv")).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert!(lines[0].starts_with("name,group,valid_pixels,epe,"), "{csv}");
    assert!(lines[0].contains("noc-epe"), "the occlusion mask gives non-occluded columns: {csv}");
    assert!(lines[1].starts_with("left_rgb,") && lines[2].starts_with("mean:all,"), "{csv}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("eval.json")).unwrap()).unwrap();
    assert_eq!(json["rows"].as_array().unwrap().len(), 1);
    let epe = json["rows"][0]["all"]["epe"].as_f64().unwrap();
    let mean = json["aggregates"][0]["all"]["epe"].as_f64().unwrap();
    assert!(epe > 0.0 && (epe - mean).abs() < 1e-9, "one image: its row is the mean ({epe} vs {mean})");
}

#[test]
fn eval_reads_a_middlebury_layout_and_honours_limit() {
    let Some(w) = weights("eval_middlebury") else { return };
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().join("MiddEval3");
    let cones = cones_dir();
    for scene in ["Cones", "ConesAgain"] {
        let d = root.join(scene);
        std::fs::create_dir_all(&d).unwrap();
        for (from, to) in [("left_rgb.png", "im0.png"), ("right_rgb.png", "im1.png"), ("disp_left.pfm", "disp0GT.pfm")]
        {
            std::fs::copy(cones.join(from), d.join(to)).unwrap();
        }
    }
    let out = tmp.path().join("eval");
    let o = dgstereo(&[
        "eval",
        "--dataset",
        "middlebury",
        "--root",
        root.to_str().unwrap(),
        "--limit",
        "1",
        "--iters",
        "1",
        "--max-size",
        "64",
        "--weights",
        w.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_no_panic(&o);
    let (stdout, stderr) = text(&o);
    assert!(o.status.success(), "{stdout}\n{stderr}");
    assert!(stdout.contains("protocol: middlebury (MeanPerImage; headline bad-2)"), "{stdout}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("eval.json")).unwrap()).unwrap();
    let rows = json["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 1, "--limit 1");
    assert_eq!(rows[0]["name"], "Cones");
    assert!(rows[0]["noc"].is_null(), "no mask0nocc.png, no non-occluded scores");
}

/// Output into a pipe whose reader has gone (`dgstereo bench | head -1`) ends the process by
/// SIGPIPE, quietly, instead of a panic with a backtrace.
#[cfg(unix)]
#[test]
fn a_closed_pipe_ends_the_command_quietly() {
    use std::os::unix::process::ExitStatusExt;
    use std::process::{Command, Stdio};
    let mut child = Command::new(env!("CARGO_BIN_EXE_dgstereo"))
        .args(["bench", "--size", "32x32", "--iters", "1", "--runs", "1", "--warmup", "0"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the dgstereo binary runs");
    // Close the reading end before the bench prints its first line (after a whole pass).
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_eq!(out.status.signal(), Some(libc::SIGPIPE), "{:?}: {stderr}", out.status);
}
