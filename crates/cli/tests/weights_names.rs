//! Weights by name from the command line: `weights list`, `weights fetch` from a loopback server
//! standing in for Dropbox, `infer --weights NAME` using the cached file, `--offline` refusing a
//! missing one with the fetch command, and a server that never answers ending both commands
//! with an error within `DGSTEREO_HTTP_TIMEOUT`.

mod common;
#[path = "../../weights/tests/loopback/mod.rs"]
mod loopback;

use std::io::Write;
use std::path::Path;
use std::process::{Command, Output};

use common::{cones_dir, text};
use dgstereo_core::shared::shared_dir_for_test;

/// Runs the binary with `args`, its cache in `cache` and `models.zip` at `zip_url`.
fn run(args: &[&str], cache: &Path, zip_url: &str) -> Output {
    run_with(args, cache, zip_url, &[])
}

/// As [`run`], with more variables.
fn run_with(args: &[&str], cache: &Path, zip_url: &str, vars: &[(&str, &str)]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dgstereo"))
        .args(args)
        .env("DGSTEREO_CACHE", cache)
        .env("DGSTEREO_RAFT_STEREO_MODELS_URL", zip_url)
        .env_remove("DGSTEREO_OFFLINE")
        .env_remove("HF_HUB_OFFLINE")
        .env_remove("DGSTEREO_HTTP_TIMEOUT")
        .envs(vars.iter().copied())
        .output()
        .expect("the dgstereo binary runs")
}

#[test]
fn list_names_every_checkpoint_with_its_licence() {
    let cache = tempfile::tempdir().unwrap();
    let o = run(&["weights", "list"], cache.path(), "http://127.0.0.1:9/none");
    let out = text(&o);
    assert!(o.status.success(), "{out}");
    for name in dgstereo_weights::CATALOG.iter().map(|w| w.name) {
        assert!(out.contains(name), "{name}: {out}");
    }
    assert!(out.contains("Apache-2.0") && out.contains("CC-BY-NC-4.0") && out.contains("MIT"), "{out}");
    assert_eq!(out.matches("not cached").count(), dgstereo_weights::CATALOG.len(), "{out}");
    // How each is checked: the hub's files against their published SHA-256, the others for
    // structure; DEFOM-Stereo ViT-L carries Depth Anything V2 Large's licence.
    let block = |name: &str| out.split("\n\n").find(|b| b.starts_with(&format!("{name} "))).unwrap_or_default();
    assert!(block("depth-anything-v2-small").contains("verified: SHA-256 pinned"), "{out}");
    assert!(block("raftstereo-middlebury").contains("verified: structure only"), "{out}");
    assert!(block("defomstereo-vitl-kitti").contains("CC-BY-NC-4.0"), "{out}");
    assert!(!block("defomstereo-vits-sceneflow").contains("CC-BY-NC-4.0"), "{out}");
    assert!(block("igev-stereo-sceneflow").contains("drive.google.com/drive/folders/"), "{out}");
    let o = run(&["weights", "fetch", "raftstereo-kitti"], cache.path(), "http://127.0.0.1:9/none");
    assert!(!o.status.success() && text(&o).contains("raftstereo-middlebury"), "{}", text(&o));
}

#[test]
fn a_fetched_name_runs_offline_and_a_missing_one_names_the_fetch_command() {
    let Some(shared) = shared_dir_for_test("weights_names", "golden/raft_stereo_random.pth") else { return };
    let weights = shared.join("golden/raft_stereo_random.pth");
    let server = loopback::Server::start();
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let options = zip::write::FileOptions::default().compression_method(zip::CompressionMethod::Stored);
    zip.start_file("models/raftstereo-middlebury.pth", options).unwrap();
    zip.write_all(&std::fs::read(&weights).unwrap()).unwrap();
    server.file("/models.zip", zip.finish().unwrap().into_inner());
    let url = format!("{}/models.zip", server.base());
    let cache = tempfile::tempdir().unwrap();
    let cones = cones_dir();
    let (left, right) = (cones.join("left_rgb.png"), cones.join("right_rgb.png"));
    let infer = |extra: &[&str]| {
        let out = cache.path().join("out");
        let mut args = vec!["infer", "-l", left.to_str().unwrap(), "-r", right.to_str().unwrap()];
        args.extend_from_slice(&["--iters", "1", "--max-size", "160", "--out", out.to_str().unwrap()]);
        args.extend_from_slice(extra);
        run(&args, cache.path(), &url)
    };

    let o = infer(&["--weights", "raftstereo-middlebury", "--offline"]);
    assert!(!o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("dgstereo weights fetch raftstereo-middlebury"), "{}", text(&o));
    assert!(server.requests().is_empty());

    let o = run(&["weights", "fetch", "raftstereo-middlebury"], cache.path(), &url);
    assert!(o.status.success(), "{}", text(&o));
    let kept = cache.path().join("raft-stereo/raftstereo-middlebury.pth");
    assert!(String::from_utf8_lossy(&o.stdout).contains(kept.to_str().unwrap()), "{}", text(&o));
    assert_eq!(std::fs::read(&kept).unwrap(), std::fs::read(&weights).unwrap());

    let o = infer(&["--weights", "raftstereo-middlebury", "--offline"]);
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(server.requests().len(), 1);
    let o = run(&["weights", "list"], cache.path(), &url);
    assert!(text(&o).contains(&format!("cached: {}", kept.display())), "{}", text(&o));
}

#[test]
fn a_server_that_never_answers_ends_fetch_and_infer_with_an_error_naming_it() {
    let server = loopback::Server::silent();
    let url = format!("{}/models.zip", server.base());
    let cache = tempfile::tempdir().unwrap();
    let timeout = [("DGSTEREO_HTTP_TIMEOUT", "0.5")];
    let o = run_with(&["weights", "fetch", "raftstereo-eth3d"], cache.path(), &url, &timeout);
    let out = text(&o);
    assert!(!o.status.success(), "{out}");
    assert!(out.contains(&url) && out.contains("no answer within 0.5 s") && out.contains("fetch again"), "{out}");
    let cones = cones_dir();
    let (left, right) = (cones.join("left_rgb.png"), cones.join("right_rgb.png"));
    let args = ["infer", "-l", left.to_str().unwrap(), "-r", right.to_str().unwrap(), "--weights", "raftstereo-eth3d"];
    let o = run_with(&args, cache.path(), &url, &timeout);
    assert!(!o.status.success() && text(&o).contains("no answer within 0.5 s"), "{}", text(&o));
    let o = run_with(&["weights", "list"], cache.path(), &url, &[("DGSTEREO_HTTP_TIMEOUT", "soon")]);
    assert!(!o.status.success() && text(&o).contains("DGSTEREO_HTTP_TIMEOUT"), "{}", text(&o));
}
