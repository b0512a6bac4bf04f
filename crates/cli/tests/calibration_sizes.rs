//! `dgstereo infer --calib` applies a calibration to the size it was made for: a crop or a resize
//! to another aspect ratio is an error naming both sizes until `--calib-crop` / `--calib-scale`
//! state it; a resize at the same aspect ratio is applied with a note. Pairs under the network's
//! minimum size are refused with their size. The bundled default runs one iteration at the
//! pairs' own size (`--min-size off`).

mod common;

use std::path::Path;

use common::{cones_dir, dgstereo, text};
use dgstereo_data::resize::resize_rgb;
use dgstereo_data::{RgbImage, load_rgb, read_disparity, save_rgb};

/// Cones' views cut to `width x height` at `(x0, y0)`, then resized by `(sx, sy)`, as
/// `dir/scene_left.png` and `dir/scene_right.png` (the pair `scene`).
fn cones_pair(dir: &Path, (x0, y0, width, height): (usize, usize, usize, usize), (sx, sy): (f64, f64)) {
    for side in ["left", "right"] {
        let full = load_rgb(cones_dir().join(format!("{side}_rgb.png"))).unwrap();
        let cut = RgbImage::from_fn(width, height, |x, y| full.get(x0 + x, y0 + y));
        let made = if (sx, sy) == (1.0, 1.0) { cut } else { resize_rgb(&cut, sx, sy) };
        save_rgb(dir.join(format!("scene_{side}.png")), &made).unwrap();
    }
}

/// `infer` on `dir`'s pair with `extra` flags, writing depth into `dir/out`.
fn infer_depth(dir: &Path, calib: &Path, extra: &[&str]) -> std::process::Output {
    let (l, r, out) = (dir.join("scene_left.png"), dir.join("scene_right.png"), dir.join("out"));
    let mut args = vec!["infer", "-l", l.to_str().unwrap(), "-r", r.to_str().unwrap()];
    args.extend(["--save", "pfm,depth", "--calib", calib.to_str().unwrap(), "--iters", "1", "--min-size", "off"]);
    args.extend(["--out", out.to_str().unwrap()]);
    args.extend_from_slice(extra);
    dgstereo(&args)
}

/// A Middlebury calibration of Cones at 450x375: f 750 px, principal point (225, 187.5), 10 cm.
fn write_calibration(dir: &Path) -> std::path::PathBuf {
    let calib = dir.join("calib.txt");
    std::fs::write(
        &calib,
        "cam0=[750 0 225; 0 750 187.5; 0 0 1]\ncam1=[750 0 225; 0 750 187.5; 0 0 1]\ndoffs=0\nbaseline=100\nwidth=450\nheight=375\nndisp=64\n",
    )
    .unwrap();
    calib
}

/// Checks depth against `focal_baseline / d` at every pixel of positive disparity and `inf`
/// elsewhere; returns the count of pixels without depth.
fn assert_depth(dir: &Path, focal_baseline: f32) -> usize {
    let disp = read_disparity(dir.join("out/scene_disparity.pfm")).unwrap();
    let depth = read_disparity(dir.join("out/scene_depth.pfm")).unwrap();
    let (mut checked, mut none) = (0, 0);
    for (z, d) in depth.data.iter().zip(&disp.data) {
        if *d > 0.0 {
            assert!((z - focal_baseline / d).abs() <= 1e-4 * z, "depth {z} for disparity {d}");
            checked += 1;
        } else {
            assert_eq!(*z, f32::INFINITY, "no depth for disparity {d}");
            none += 1;
        }
    }
    assert!(checked > 0);
    none
}

#[test]
fn a_crop_needs_its_corner_and_then_keeps_the_focal_length() {
    let tmp = tempfile::tempdir().unwrap();
    let calib = write_calibration(tmp.path());
    cones_pair(tmp.path(), (200, 150, 100, 40), (1.0, 1.0));
    let o = infer_depth(tmp.path(), &calib, &[]);
    assert!(!o.status.success(), "{}", text(&o));
    let said = text(&o);
    assert!(said.contains("450x375") && said.contains("100x40") && said.contains("--calib-crop"), "{said}");
    assert!(!tmp.path().join("out/scene_depth.pfm").exists(), "no depth from the wrong calibration");
    let o = infer_depth(tmp.path(), &calib, &["--calib-crop", "200,150"]);
    assert!(o.status.success(), "{}", text(&o));
    assert_depth(tmp.path(), 750.0 * 0.1);
    // A crop the calibrated image cannot hold is an error too.
    let o = infer_depth(tmp.path(), &calib, &["--calib-crop", "400,0"]);
    assert!(!o.status.success() && text(&o).contains("does not fit"), "{}", text(&o));
}

#[test]
fn a_resize_to_another_aspect_ratio_needs_its_factors() {
    let tmp = tempfile::tempdir().unwrap();
    let calib = write_calibration(tmp.path());
    // Half as wide, as tall: 225x375.
    cones_pair(tmp.path(), (0, 0, 450, 375), (0.5, 1.0));
    let o = infer_depth(tmp.path(), &calib, &[]);
    assert!(!o.status.success() && text(&o).contains("225x375"), "{}", text(&o));
    let o = infer_depth(tmp.path(), &calib, &["--calib-scale", "0.5,1"]);
    assert!(o.status.success(), "{}", text(&o));
    assert_depth(tmp.path(), 375.0 * 0.1);
    let o = infer_depth(tmp.path(), &calib, &["--calib-scale", "0"]);
    assert!(!o.status.success() && text(&o).contains("positive"), "{}", text(&o));
}

#[test]
fn a_resize_at_the_same_aspect_ratio_is_applied_with_a_note() {
    let tmp = tempfile::tempdir().unwrap();
    let calib = write_calibration(tmp.path());
    cones_pair(tmp.path(), (0, 0, 450, 375), (0.5, 0.5));
    let o = infer_depth(tmp.path(), &calib, &[]);
    assert!(o.status.success(), "{}", text(&o));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("note: calibration") && err.contains("450x375") && err.contains("225x188"), "{err}");
    // fx scaled by 225/450.
    let none = assert_depth(tmp.path(), 375.0 * 0.1);
    // Pixels without depth are counted on the pair's line.
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("scene: 225x188"), "{out}");
    assert_eq!(out.contains(&format!(", {none} px without depth")), none > 0, "{out}");
}

#[test]
fn pairs_under_the_networks_minimum_are_refused_with_their_size() {
    let tmp = tempfile::tempdir().unwrap();
    for (name, (w, h)) in [("dot", (1, 1)), ("strip", (200, 20))] {
        for side in ["left", "right"] {
            save_rgb(tmp.path().join(format!("{name}_{side}.png")), &RgbImage::new(w, h)).unwrap();
        }
        let (l, r) = (tmp.path().join(format!("{name}_left.png")), tmp.path().join(format!("{name}_right.png")));
        let out = tmp.path().join("out");
        let args = ["infer", "-l", l.to_str().unwrap(), "-r", r.to_str().unwrap(), "--iters", "1", "--out"];
        let o = dgstereo(&[&args[..], &[out.to_str().unwrap()]].concat());
        assert!(!o.status.success(), "{}", text(&o));
        let said = text(&o);
        assert!(said.contains(&format!("{w}x{h} pixels")) && said.contains("at least 32"), "{said}");
        assert!(!said.contains("panicked"), "{said}");
    }
}
