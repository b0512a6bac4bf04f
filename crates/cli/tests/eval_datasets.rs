//! `dgstereo eval` on the paper's benchmark layouts: a MiddEval3 folder with `--split`, the split
//! folder itself, and the errors that say which root or option a data set expects.

mod common;

use std::path::{Path, PathBuf};

use common::{dgstereo, text};
use dgstereo_core::shared::shared_dir_for_test;
use dgstereo_data::{DisparityMap, RgbImage, save_rgb, write_disparity};

fn weights(test: &str) -> Option<PathBuf> {
    shared_dir_for_test(test, "golden/raft_stereo_random.pth").map(|s| s.join("golden/raft_stereo_random.pth"))
}

/// A fake MiddEval3 folder: `trainingH` with two scenes of 64x48 and `trainingQ` with one of
/// 48x32 (the network takes at least 32 pixels a side); the right view is the left shifted by 2 px, the ground truth 2 px with one unknown pixel.
fn fake_middeval3(root: &Path) {
    for (split, scenes, width, height) in [("H", &["Adirondack", "Piano"][..], 64, 48), ("Q", &["Piano"][..], 48, 32)] {
        for scene in scenes {
            let dir = root.join(format!("training{split}/{scene}"));
            std::fs::create_dir_all(&dir).unwrap();
            let texture = |x: usize, y: usize| {
                let v = ((x * 37 + y * 11) % 23) as f32 * 10.0;
                [v, 255.0 - v, (x * 5 % 255) as f32]
            };
            save_rgb(dir.join("im0.png"), &RgbImage::from_fn(width, height, texture)).unwrap();
            save_rgb(dir.join("im1.png"), &RgbImage::from_fn(width, height, |x, y| texture(x + 2, y))).unwrap();
            let mut gt = DisparityMap::filled(width, height, 2.0);
            gt.set(0, 0, f32::INFINITY);
            write_disparity(dir.join("disp0GT.pfm"), &gt).unwrap();
        }
    }
}

fn eval(root: &Path, extra: &[&str], weights: &Path, out: &Path) -> std::process::Output {
    let mut args = vec![
        "eval",
        "--dataset",
        "middlebury",
        "--root",
        root.to_str().unwrap(),
        "--iters",
        "1",
        "--weights",
        weights.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    dgstereo(&args)
}

fn scored_rows(out: &Path) -> Vec<String> {
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("eval.json")).unwrap()).unwrap();
    json["rows"].as_array().unwrap().iter().map(|r| r["name"].as_str().unwrap().to_string()).collect()
}

#[test]
fn eval_takes_the_middeval3_folder_and_a_split() {
    let Some(w) = weights("eval_middeval3_split") else { return };
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().join("MiddEval3");
    fake_middeval3(&root);
    let out = tmp.path().join("eval-h");
    let o = eval(&root, &["--split", "H"], &w, &out);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    assert!(!t.contains("panicked"), "{t}");
    assert!(t.contains("protocol: middlebury (MeanPerImage; headline bad-2)"), "{t}");
    assert_eq!(scored_rows(&out), ["Adirondack", "Piano"]);
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("eval.json")).unwrap()).unwrap();
    assert_eq!(json["rows"][0]["all"]["valid_pixels"], 64 * 48 - 1, "the H scene, less its unknown pixel");

    // The split folder as the root still works, with or without --split.
    let out_q = tmp.path().join("eval-q");
    let o = eval(&root.join("trainingQ"), &[], &w, &out_q);
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(scored_rows(&out_q), ["Piano"]);
    let o = eval(&root.join("trainingQ"), &["--split", "q"], &w, &out_q);
    assert!(o.status.success(), "{}", text(&o));
}

#[test]
fn eval_says_which_root_and_options_a_data_set_takes() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().join("MiddEval3");
    fake_middeval3(&root);
    let out = tmp.path().join("eval");
    let weights = Path::new("/nonexistent/weights.pth");
    let cases: [(&[&str], &[&str]); 4] = [
        (&["--dataset", "middlebury", "--root"], &["MiddEval3 folder", "--split Q, H or F"]),
        (&["--dataset", "middlebury", "--split", "F", "--root"], &["no trainingF/", "trainingQ, trainingH"]),
        (&["--dataset", "kitti2015", "--weather", "rainy", "--root"], &["--weather", "drivingstereo", "kitti2015"]),
        (&["--dataset", "middlebury", "--split", "X", "--root"], &["Q, H or F"]),
    ];
    for (args, needles) in cases {
        let mut all: Vec<&str> = vec!["eval"];
        all.extend_from_slice(args);
        all.extend([root.to_str().unwrap(), "--weights", weights.to_str().unwrap(), "--out", out.to_str().unwrap()]);
        let o = dgstereo(&all);
        let t = text(&o);
        assert!(!o.status.success(), "{all:?}\n{t}");
        assert!(!t.contains("panicked"), "{t}");
        for needle in needles {
            assert!(t.contains(needle), "{all:?}: no '{needle}' in\n{t}");
        }
    }
}

/// `--shard 0/2` and `1/2`, merged with `--merge`, write the unsharded evaluation's table.
#[test]
fn shards_merge_into_the_unsharded_table() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("scenes");
    for (k, shift) in [1usize, 2, 3].into_iter().enumerate() {
        let scene = root.join(format!("scene-{k}"));
        std::fs::create_dir_all(&scene).unwrap();
        let texture = |x: usize, y: usize| {
            let v = ((x * 37 + y * 11 + k * 5) % 23) as f32 * 10.0;
            [v, 255.0 - v, (x * 5 % 255) as f32]
        };
        save_rgb(scene.join("im0.png"), &RgbImage::from_fn(48, 32, texture)).unwrap();
        save_rgb(scene.join("im1.png"), &RgbImage::from_fn(48, 32, |x, y| texture(x + shift, y))).unwrap();
        write_disparity(scene.join("disp0GT.pfm"), &DisparityMap::filled(48, 32, shift as f32)).unwrap();
    }
    let run = |out: &Path, extra: &[&str]| {
        let mut args = vec!["eval", "--dataset", "folder", "--root", root.to_str().unwrap(), "--iters", "2"];
        args.extend_from_slice(&["--min-size", "off", "--out", out.to_str().unwrap()]);
        args.extend_from_slice(extra);
        let o = dgstereo(&args);
        assert!(o.status.success(), "{}", text(&o));
    };
    let (whole, first, second, merged) =
        (dir.path().join("whole"), dir.path().join("s0"), dir.path().join("s1"), dir.path().join("merged"));
    run(&whole, &[]);
    run(&first, &["--shard", "0/2"]);
    run(&second, &["--shard", "1/2"]);
    assert_eq!(scored_rows(&first).len(), 2);
    assert_eq!(scored_rows(&second).len(), 1);
    let o = dgstereo(&[
        "eval",
        "--merge",
        second.to_str().unwrap(),
        first.to_str().unwrap(),
        "--out",
        merged.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    for file in ["eval.csv", "eval.json"] {
        let (a, b) = (std::fs::read(whole.join(file)).unwrap(), std::fs::read(merged.join(file)).unwrap());
        assert!(a == b, "{file}: merged differs from unsharded:\n{}", String::from_utf8_lossy(&b));
    }
    let o = dgstereo(&["eval", "--merge", first.to_str().unwrap(), "--out", merged.to_str().unwrap()]);
    assert!(!o.status.success() && text(&o).contains("0..2"), "{}", text(&o));
}
