//! DEFOM-Stereo from an official checkpoint everywhere the command line takes a model: the seeded
//! weights of the conformance file written as an official `.pth` (the released files' layout,
//! under `module.`), served by name from a loopback server standing in for Google Drive, run by
//! `infer --weights defomstereo-vits-sceneflow`, `eval` (which prints the paper's Table 1 figures
//! beside ours) and `bench --weights`; and a name of an architecture without a network here
//! refused before anything is fetched.

mod common;
#[path = "../../weights/tests/loopback/mod.rs"]
mod loopback;
#[path = "../../../tests/support/official_pth.rs"]
mod official_pth;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use common::{cones_dir, text};
use dgstereo_core::shared::shared_dir_for_test;
use dgstereo_data::{DisparityMap, RgbImage, read_disparity, save_rgb, write_disparity};
use dgstereo_weights::Source;

const GOLDEN: &str = "golden/defom_stereo_vits_seeded.activations.safetensors";

/// The seeded DEFOM-Stereo ViT-S written as `dir/defomstereo_vits_sceneflow.pth`.
fn seeded_pth(test: &str, dir: &Path) -> Option<PathBuf> {
    let golden = shared_dir_for_test(test, GOLDEN)?.join(GOLDEN);
    let (state, _) = dgstereo_model::seeded::golden_state_dict(&golden).unwrap();
    let path = dir.join("defomstereo_vits_sceneflow.pth");
    official_pth::write_pth(&state, "module.", &path);
    Some(path)
}

/// Runs the binary with `args`, its cache in `cache` and Google Drive at `drive`.
fn run(args: &[&str], cache: &Path, drive: &str) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dgstereo"))
        .args(args)
        .env("DGSTEREO_CACHE", cache)
        .env("DGSTEREO_GOOGLE_DRIVE_URL", drive)
        .env_remove("DGSTEREO_OFFLINE")
        .env_remove("HF_HUB_OFFLINE")
        .output()
        .expect("the dgstereo binary runs")
}

/// A MiddEval3 `trainingH` folder with one 64x48 scene: the right view is the left shifted by
/// 2 px, the ground truth 2 px.
fn middlebury_scene(root: &Path) {
    let dir = root.join("trainingH/Piano");
    std::fs::create_dir_all(&dir).unwrap();
    let texture = |x: usize, y: usize| {
        let v = ((x * 37 + y * 11) % 23) as f32 * 10.0;
        [v, 255.0 - v, (x * 5 % 255) as f32]
    };
    save_rgb(dir.join("im0.png"), &RgbImage::from_fn(64, 48, texture)).unwrap();
    save_rgb(dir.join("im1.png"), &RgbImage::from_fn(64, 48, |x, y| texture(x + 2, y))).unwrap();
    write_disparity(dir.join("disp0GT.pfm"), &DisparityMap::filled(64, 48, 2.0)).unwrap();
}

#[test]
fn a_defom_checkpoint_runs_by_name_in_infer_and_by_file_in_eval_and_bench() {
    let tmp = tempfile::tempdir().unwrap();
    let Some(pth) = seeded_pth("defom_weights", tmp.path()) else { return };
    let server = loopback::Server::start();
    let entry = dgstereo_weights::find("defomstereo-vits-sceneflow").unwrap();
    let Source::GoogleDrive { file, ids } = entry.source else { panic!("{entry:?} is on Google Drive") };
    // The release's first id answers with the file at once, naming it, as Drive does.
    let disposition = format!("attachment; filename=\"{file}\"");
    let body = std::fs::read(&pth).unwrap();
    server.file_with(
        &format!("/download?id={}&export=download", ids[0]),
        body,
        &[("Content-Disposition", &disposition)],
        true,
    );
    let cache = tmp.path().join("cache");
    let drive = server.base().to_string();
    let cones = cones_dir();
    let (left, right) = (cones.join("left_rgb.png"), cones.join("right_rgb.png"));
    let out = tmp.path().join("infer");
    let o = run(
        &[
            "infer",
            "-l",
            left.to_str().unwrap(),
            "-r",
            right.to_str().unwrap(),
            "--weights",
            entry.name,
            "--iters",
            "2",
            "--max-size",
            "128",
            "--out",
            out.to_str().unwrap(),
        ],
        &cache,
        &drive,
    );
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    assert!(t.contains("DEFOM-Stereo: Depth Anything V2 vits") && t.contains("preset: DEFOM-Stereo"), "{t}");
    let disparity = read_disparity(out.join("rgb_disparity.pfm")).unwrap();
    assert_eq!((disparity.width, disparity.height), (450, 375));
    assert!(disparity.data.iter().all(|d| d.is_finite()), "{t}");
    let kept = cache.join("google-drive").join(file);
    assert_eq!(std::fs::read(&kept).unwrap(), std::fs::read(&pth).unwrap());

    let root = tmp.path().join("MiddEval3");
    middlebury_scene(&root);
    let scores = tmp.path().join("eval");
    let o = run(
        &[
            "eval",
            "--dataset",
            "middlebury",
            "--root",
            root.to_str().unwrap(),
            "--split",
            "H",
            "--iters",
            "2",
            "--weights",
            pth.to_str().unwrap(),
            "--out",
            scores.to_str().unwrap(),
        ],
        &cache,
        &drive,
    );
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    assert!(t.contains("DEFOM-Stereo: Depth Anything V2 vits"), "{t}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(scores.join("eval.json")).unwrap()).unwrap();
    assert_eq!(json["rows"][0]["all"]["valid_pixels"], 64 * 48, "{json}");
    // A model of the paper's Table 1 on one of its data sets: the published figures beside ours.
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("published: DEFOM-Stereo (the model of defomstereo-vits-sceneflow)"), "{t}");
    let epe = json["aggregates"][0]["all"]["epe"].as_f64().unwrap_or(f64::NAN);
    assert!(stdout.contains(&format!("Midd-H: EPE 0.84 (ours {epe:.3}), D2 6.03 % (ours ")), "{epe} {t}");
    assert!(stdout.contains("not the paper's protocol: 2 iterations (the paper: 32)"), "{t}");

    let o = run(
        &["bench", "--weights", entry.name, "--size", "64x96", "--iters", "2", "--runs", "1", "--warmup", "0"],
        &cache,
        &drive,
    );
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    assert!(t.contains("DEFOM-Stereo: Depth Anything V2 vits"), "{t}");
    // One download served all three commands.
    assert_eq!(server.requests().len(), 1, "{:?}", server.requests());
}

/// The IGEV-Stereo name is a file downloaded by hand: a command that loads it says where to get
/// it and where to put it, asks no server, and `weights fetch` says the same.
#[test]
fn a_name_downloaded_by_hand_says_where_to_get_it() {
    let server = loopback::Server::start();
    let cache = tempfile::tempdir().unwrap();
    let cones = cones_dir();
    let (left, right) = (cones.join("left_rgb.png"), cones.join("right_rgb.png"));
    let args =
        ["infer", "-l", left.to_str().unwrap(), "-r", right.to_str().unwrap(), "--weights", "igev-stereo-sceneflow"];
    let o = run(&args, cache.path(), server.base());
    let t = text(&o);
    assert!(!o.status.success() && !t.contains("panicked"), "{t}");
    let place = cache.path().join("igev-stereo-sceneflow").join("sceneflow.pth");
    assert!(t.contains("drive.google.com/drive/folders/") && t.contains(&place.display().to_string()), "{t}");
    assert!(server.requests().is_empty());
    let o = run(&["weights", "fetch", "igev-stereo-sceneflow"], cache.path(), server.base());
    assert!(text(&o).contains("drive.google.com/drive/folders/"), "{}", text(&o));
}
