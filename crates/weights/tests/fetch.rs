//! Fetching named weights from a loopback server that stands in for the hub and for Dropbox:
//! a good fetch (through a redirect, as both real servers answer), an interrupted one resumed,
//! corrupt ones refused with nothing kept, two concurrent fetches of one name, offline mode.
//! The fixtures are the random-weight checkpoints of `../shared/golden` (the official code's
//! layout), so the structural checks run on real files.

mod loopback;

use std::io::Write;
use std::path::{Path, PathBuf};

use dgstereo_core::shared::shared_dir_for_test;
use dgstereo_weights::{Cache, Fetcher, Role, Sources, find};
use loopback::Server;

const VITS_PATH: &str = "/depth-anything/Depth-Anything-V2-Small/resolve/main/depth_anything_v2_vits.pth";
const COMMIT: &str = "0123456789abcdef0123456789abcdef01234567";

fn golden(test: &str, file: &str) -> Option<PathBuf> {
    shared_dir_for_test(test, &format!("golden/{file}")).map(|s| s.join("golden").join(file))
}

fn sha256(bytes: &[u8]) -> String {
    use sha2::Digest;
    sha2::Sha256::digest(bytes).iter().map(|b| format!("{b:02x}")).collect()
}

/// Serves `body` as the hub serves a large file: the resolve URL redirects to a CDN path with
/// the commit and the etag (the SHA-256 of `etag_of`).
fn serve_vits(server: &Server, body: Vec<u8>, etag_of: &[u8]) {
    let etag = format!("\"{}\"", sha256(etag_of));
    let size = etag_of.len().to_string();
    server.redirect(
        VITS_PATH,
        "/cdn/vits",
        &[("x-repo-commit", COMMIT), ("x-linked-etag", &etag), ("x-linked-size", &size)],
    );
    server.file("/cdn/vits", body);
}

/// A `models.zip` holding `members` (name, file), stored uncompressed, served behind a redirect
/// at `/s/models.zip` as Dropbox serves it.
fn serve_models_zip(server: &Server, members: &[(&str, &Path)]) -> Vec<u8> {
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let options = zip::write::FileOptions::default().compression_method(zip::CompressionMethod::Stored);
    for (name, path) in members {
        zip.start_file(format!("models/{name}"), options).unwrap();
        zip.write_all(&std::fs::read(path).unwrap()).unwrap();
    }
    let bytes = zip.finish().unwrap().into_inner();
    server.redirect("/s/models.zip", "/cdn/models.zip", &[]);
    server.file("/cdn/models.zip", bytes.clone());
    bytes
}

fn fetcher(server: &Server, cache: &Path) -> Fetcher {
    let sources =
        Sources { hub: server.base().to_string(), models_zip: format!("{}/s/models.zip?dl=1", server.base()) };
    Fetcher::new(Cache::at(cache.to_path_buf()), sources)
}

/// Every file under `dir`, relative, sorted.
fn files_under(dir: &Path) -> Vec<String> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).into_iter().flatten().flatten() {
            let p = e.path();
            if p.is_dir() && !p.is_symlink() {
                stack.push(p);
            } else {
                out.push(p.strip_prefix(dir).unwrap().display().to_string());
            }
        }
    }
    out.sort();
    out
}

#[test]
fn a_hub_file_is_fetched_through_the_redirect_into_the_hugging_face_layout() {
    let Some(vits) = golden("hub_fetch", "depth_anything_v2_vits_random.pth") else { return };
    let body = std::fs::read(&vits).unwrap();
    let server = Server::start();
    serve_vits(&server, body.clone(), &body);
    let cache = tempfile::tempdir().unwrap();
    let f = fetcher(&server, cache.path());
    let path = f.resolve(Path::new("depth-anything-v2-small"), Role::Prior, "prior").unwrap();
    let expected = format!(
        "huggingface/hub/models--depth-anything--Depth-Anything-V2-Small/snapshots/{COMMIT}/depth_anything_v2_vits.pth"
    );
    assert_eq!(path, cache.path().join(expected));
    assert_eq!(std::fs::read(&path).unwrap(), body);
    // Cached: found offline, with the server's requests unchanged.
    let before = server.requests().len();
    let again = f.clone().offline(true).resolve(Path::new("depth-anything-v2-small"), Role::Prior, "prior").unwrap();
    assert_eq!((again, server.requests().len()), (path.clone(), before));
    // Another cache that shares this one as its Hugging Face cache (as Python's) finds it too.
    let other = tempfile::tempdir().unwrap();
    let shared = Cache::at(other.path().to_path_buf()).with_shared_hub(cache.path().join("huggingface/hub"));
    assert_eq!(shared.find(find("depth-anything-v2-small").unwrap()), Some(path));
}

#[test]
fn models_zip_is_fetched_through_a_redirect_and_each_checkpoint_kept() {
    let (Some(default), Some(realtime)) =
        (golden("zip_fetch", "raft_stereo_random.pth"), golden("zip_fetch", "raft_stereo_realtime_random.pth"))
    else {
        return;
    };
    let server = Server::start();
    serve_models_zip(&server, &[("raftstereo-sceneflow.pth", &default), ("raftstereo-realtime.pth", &realtime)]);
    let cache = tempfile::tempdir().unwrap();
    let f = fetcher(&server, cache.path());
    let path = f.resolve(Path::new("raftstereo-realtime"), Role::Stereo, "weights").unwrap();
    assert_eq!(path, cache.path().join("raft-stereo/raftstereo-realtime.pth"));
    assert_eq!(std::fs::read(&path).unwrap(), std::fs::read(&realtime).unwrap());
    // One download gave both; the archive itself is not kept.
    let sceneflow =
        f.clone().offline(true).resolve(Path::new("raftstereo-sceneflow"), Role::Stereo, "weights").unwrap();
    assert_eq!(std::fs::read(sceneflow).unwrap(), std::fs::read(&default).unwrap());
    assert_eq!(files_under(&cache.path().join("raft-stereo")), ["raftstereo-realtime.pth", "raftstereo-sceneflow.pth"]);
    // A name the archive lacked is an error after the download, not a file.
    let e = f.resolve(Path::new("raftstereo-eth3d"), Role::Stereo, "weights").unwrap_err().to_string();
    assert!(e.contains("raftstereo-eth3d.pth"), "{e}");
}

#[test]
fn an_interrupted_download_resumes_where_it_broke() {
    let (Some(default), Some(vits)) =
        (golden("resume", "raft_stereo_random.pth"), golden("resume", "depth_anything_v2_vits_random.pth"))
    else {
        return;
    };
    let server = Server::start();
    let zip = serve_models_zip(&server, &[("raftstereo-sceneflow.pth", &default)]);
    let body = std::fs::read(&vits).unwrap();
    serve_vits(&server, body.clone(), &body);
    let cache = tempfile::tempdir().unwrap();
    let f = fetcher(&server, cache.path());
    for (name, role, cdn, len) in [
        ("raftstereo-sceneflow", Role::Stereo, "/cdn/models.zip", zip.len()),
        ("depth-anything-v2-small", Role::Prior, "/cdn/vits", body.len()),
    ] {
        server.cut_next(cdn, 3 << 20);
        let e = f.resolve(Path::new(name), role, "weights").unwrap_err().to_string();
        assert!(f.cache().find(find(name).unwrap()).is_none(), "{name}: a broken download left a file: {e}");
        let path = f.resolve(Path::new(name), role, "weights").unwrap();
        assert!(path.is_file());
        // The second full request asked for the rest only.
        let ranges: Vec<_> = server.requests().into_iter().filter(|r| r.path == cdn).filter_map(|r| r.range).collect();
        let resumed = ranges.iter().filter_map(|r| r.strip_prefix("bytes=")?.strip_suffix('-')?.parse::<usize>().ok());
        assert!(resumed.clone().any(|from| from >= 3 << 20 && from < len), "{name}: {ranges:?}");
    }
}

#[test]
fn a_corrupt_download_is_refused_and_nothing_is_kept() {
    let (Some(default), Some(realtime), Some(vits)) = (
        golden("corrupt", "raft_stereo_random.pth"),
        golden("corrupt", "raft_stereo_realtime_random.pth"),
        golden("corrupt", "depth_anything_v2_vits_random.pth"),
    ) else {
        return;
    };
    let server = Server::start();
    // The hub: one byte differs from what the etag (the SHA-256) says.
    let good = std::fs::read(&vits).unwrap();
    let mut bad = good.clone();
    bad[good.len() / 2] ^= 1;
    serve_vits(&server, bad, &good);
    // models.zip: the realtime checkpoint under the sceneflow name, and a default one.
    serve_models_zip(&server, &[("raftstereo-sceneflow.pth", &realtime), ("raftstereo-eth3d.pth", &default)]);
    let cache = tempfile::tempdir().unwrap();
    let f = fetcher(&server, cache.path());
    let e = f.resolve(Path::new("depth-anything-v2-small"), Role::Prior, "prior").unwrap_err().to_string();
    assert!(e.contains("SHA-256") && e.contains("nothing was kept"), "{e}");
    let e = f.resolve(Path::new("raftstereo-sceneflow"), Role::Stereo, "weights").unwrap_err().to_string();
    assert!(e.contains("realtime") && e.contains("nothing was kept"), "{e}");
    let kept: Vec<_> =
        files_under(cache.path()).into_iter().filter(|p| p.ends_with(".pth") || p.contains("blobs/")).collect();
    let only_locks: Vec<&String> = kept.iter().filter(|p| !p.ends_with(".lock")).collect();
    assert!(only_locks.is_empty(), "{kept:?}");
    // Not a zip at all.
    server.file("/cdn/models.zip", b"<html>moved</html>".to_vec());
    let e = f.resolve(Path::new("raftstereo-eth3d"), Role::Stereo, "weights").unwrap_err().to_string();
    assert!(e.contains("not a zip archive"), "{e}");
}

#[test]
fn two_concurrent_fetches_of_one_name_download_it_once() {
    let Some(default) = golden("concurrent", "raft_stereo_random.pth") else { return };
    let server = Server::start();
    serve_models_zip(&server, &[("raftstereo-middlebury.pth", &default)]);
    let cache = tempfile::tempdir().unwrap();
    let f = fetcher(&server, cache.path());
    let paths: Vec<PathBuf> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..2)
            .map(|_| s.spawn(|| f.resolve(Path::new("raftstereo-middlebury"), Role::Stereo, "weights").unwrap()))
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    assert_eq!(paths[0], paths[1]);
    assert_eq!(server.requests().iter().filter(|r| r.path == "/cdn/models.zip").count(), 1);
    assert_eq!(std::fs::read(&paths[0]).unwrap(), std::fs::read(&default).unwrap());
}

#[test]
fn offline_a_missing_name_is_an_error_naming_the_fetch_command_and_nothing_is_asked() {
    let server = Server::start();
    let cache = tempfile::tempdir().unwrap();
    let f = fetcher(&server, cache.path()).offline(true);
    let e = f.resolve(Path::new("raftstereo-middlebury"), Role::Stereo, "weights").unwrap_err().to_string();
    assert!(e.contains("dgstereo weights fetch raftstereo-middlebury") && e.contains("offline"), "{e}");
    assert!(server.requests().is_empty());
}

#[test]
fn names_go_to_their_option_and_unknown_names_list_the_known_ones() {
    let cache = tempfile::tempdir().unwrap();
    let f = Fetcher::new(Cache::at(cache.path().to_path_buf()), Sources::from_env()).offline(true);
    let e = f.resolve(Path::new("depth-anything-v2-base"), Role::Stereo, "weights").unwrap_err().to_string();
    assert!(e.contains("--prior-weights"), "{e}");
    let e = f.resolve(Path::new("raftstereo-eth3d"), Role::Prior, "prior").unwrap_err().to_string();
    assert!(e.contains("--weights"), "{e}");
    let e = f.resolve(Path::new("raftstereo-kitti"), Role::Stereo, "weights").unwrap_err().to_string();
    assert!(e.contains("raftstereo-middlebury") && e.contains("weights list"), "{e}");
    // A path that does not exist is left for the loader to report.
    let missing = cache.path().join("mine.pth");
    assert_eq!(f.resolve(&missing, Role::Stereo, "weights").unwrap(), missing);
}
