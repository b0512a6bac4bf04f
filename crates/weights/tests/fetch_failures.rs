//! What goes wrong on the way, from loopback servers: a server that accepts and never answers
//! and one that falls silent mid-body (short timeouts: an error naming the address and what
//! arrived, then a resumed fetch); a corrupt download refused against the published, stated or
//! pinned SHA-256 with nothing kept; a weak `ETag` that checks nothing, and says so; a static
//! mirror without the hub's headers, with and without ranges; a cached file that changed.

mod fixtures;
mod loopback;

use std::path::Path;
use std::time::Duration;

use dgstereo_core::Error;
use dgstereo_weights::{FetchOptions, Fetcher, Progress, Role, Verified, find};
use fixtures::*;
use loopback::Server;

/// A fetcher that waits `millis` for a silent server.
fn impatient(server: &Server, cache: &Path, millis: u64) -> Fetcher {
    let options = FetchOptions { timeout: Duration::from_millis(millis), ..FetchOptions::default() };
    fetcher(server, cache).with_options(options)
}

#[test]
fn a_server_that_never_answers_is_an_error_naming_the_address_within_the_timeout() {
    let server = Server::silent();
    let cache = tempfile::tempdir().unwrap();
    let f = impatient(&server, cache.path(), 300);
    for w in [vits_entry("vits-silent", None), find("raftstereo-sceneflow").unwrap()] {
        let e = f.fetch(w).unwrap_err();
        let Error::Fetch { url, cause } = e.root() else { panic!("{e}") };
        assert!(url.starts_with(server.base()), "{e}");
        assert!(cause.contains("no answer within 0.3 s") && cause.contains("DGSTEREO_HTTP_TIMEOUT"), "{e}");
        assert!(cause.contains("nothing arrived"), "{e}");
    }
    assert_eq!(server.requests().len(), 2, "one connection each");
}

#[test]
fn a_body_that_stalls_is_an_error_keeping_what_arrived_and_the_next_fetch_resumes() {
    let Some(vits) = golden("stall", "depth_anything_v2_vits_random.pth") else { return };
    let body = std::fs::read(&vits).unwrap();
    let server = Server::start();
    serve_hub_file(&server, body.clone(), &format!("\"{}\"", sha256(&body)));
    server.stall_next("/cdn/vits", 1 << 20);
    let cache = tempfile::tempdir().unwrap();
    let reports = std::sync::Arc::new(std::sync::Mutex::new(Vec::<Progress>::new()));
    let seen = reports.clone();
    let options = FetchOptions {
        timeout: Duration::from_secs(1),
        progress: Some(std::sync::Arc::new(move |p: &Progress| seen.lock().unwrap().push(p.clone()))),
        ..FetchOptions::default()
    };
    let f = fetcher(&server, cache.path()).with_options(options);
    let w = vits_entry("vits-stall", None);
    let e = f.fetch(w).unwrap_err();
    let Error::Fetch { url, cause } = e.root() else { panic!("{e}") };
    assert!(url.ends_with("/cdn/vits"), "{e}");
    assert!(cause.contains("went silent") && cause.contains("after 1048576 bytes"), "{e}");
    assert!(cause.contains("fetch again to resume"), "{e}");
    assert!(e.to_string().contains(VITS_PATH), "the hub's address is named too: {e}");
    // The resumed fetch waits longer: a busy machine may pause the server that long.
    let patient = FetchOptions { timeout: Duration::from_secs(30), ..f.options().clone() };
    let fetched = f.with_options(patient).fetch(w).unwrap();
    assert_eq!(std::fs::read(&fetched.path).unwrap(), body);
    let last = server.requests().into_iter().rfind(|r| r.path == "/cdn/vits").unwrap();
    assert_eq!(last.range.as_deref(), Some("bytes=1048576-"));
    // Progress came as data: a broken attempt's last report, then the resumed one to the end.
    let reports = reports.lock().unwrap();
    let finished: Vec<(u64, Option<u64>)> = reports.iter().filter(|p| p.finished).map(|p| (p.done, p.total)).collect();
    let total = Some(body.len() as u64);
    assert_eq!(finished, [(1 << 20, total), (body.len() as u64, total)]);
    assert!(reports.iter().all(|p| p.file == "depth_anything_v2_vits.pth"));
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
    // The hub: one byte differs from what the etag (the SHA-256) says, and from the pin.
    let good = std::fs::read(&vits).unwrap();
    let mut bad = good.clone();
    bad[good.len() / 2] ^= 1;
    serve_hub_file(&server, bad, &format!("\"{}\"", sha256(&good)));
    // models.zip: the realtime checkpoint under the sceneflow name, and a default one.
    serve_models_zip(&server, &[("raftstereo-sceneflow.pth", &realtime), ("raftstereo-eth3d.pth", &default)]);
    let cache = tempfile::tempdir().unwrap();
    let f = fetcher(&server, cache.path());
    for (w, what) in [
        (vits_entry("vits-stated", None), "the SHA-256 the server stated"),
        (vits_entry("vits-pinned", Some(&sha256(&good))), "the published SHA-256"),
    ] {
        let e = f.fetch(w).unwrap_err();
        assert!(matches!(e.root(), Error::Fetch { .. }), "{e}");
        let e = e.to_string();
        assert!(e.contains(what) && e.contains(&sha256(&good)) && e.contains("nothing was kept"), "{e}");
    }
    let e = f.resolve(Path::new("raftstereo-sceneflow"), Role::Stereo, "weights").unwrap_err().to_string();
    assert!(e.contains("realtime") && e.contains("nothing was kept"), "{e}");
    let kept: Vec<_> = files_under(cache.path()).into_iter().filter(|p| !p.ends_with(".lock")).collect();
    assert!(kept.iter().all(|p| !p.ends_with(".pth") && !p.contains("blobs/")), "{kept:?}");
    // Not a zip at all.
    server.file("/cdn/models.zip", b"<html>moved</html>".to_vec());
    let e = f.resolve(Path::new("raftstereo-eth3d"), Role::Stereo, "weights").unwrap_err().to_string();
    assert!(e.contains("not a zip archive"), "{e}");
}

#[test]
fn a_weak_etag_checks_nothing_and_the_fetch_says_structure_only_while_a_pin_still_holds() {
    let Some(vits) = golden("weak_etag", "depth_anything_v2_vits_random.pth") else { return };
    let good = std::fs::read(&vits).unwrap();
    // A byte of a tensor's data differs: the structure still shows ViT-S.
    let mut changed = good.clone();
    changed[good.len() / 2] ^= 1;
    let server = Server::start();
    serve_hub_file(&server, changed.clone(), &format!("W/\"{}\"", sha256(&good)));
    let cache = tempfile::tempdir().unwrap();
    let f = fetcher(&server, cache.path());
    let unpinned = vits_entry("vits-weak", None);
    let fetched = f.fetch(unpinned).unwrap();
    assert_eq!(fetched.verified, Verified::StructureOnly, "a weak tag is no SHA-256");
    assert_eq!(f.cache().recorded(unpinned).unwrap().map(|r| r.sha256), Some(sha256(&changed)));
    std::fs::remove_dir_all(cache.path().join("huggingface")).unwrap();
    let e = f.fetch(vits_entry("vits-weak-pinned", Some(&sha256(&good)))).unwrap_err().to_string();
    assert!(e.contains("the published SHA-256") && e.contains("nothing was kept"), "{e}");
}

#[test]
fn a_static_mirror_without_hub_headers_serves_pinned_files_with_and_without_ranges() {
    let Some(vits) = golden("mirror", "depth_anything_v2_vits_random.pth") else { return };
    let body = std::fs::read(&vits).unwrap();
    let pinned = sha256(&body);
    for ranges in [true, false] {
        let server = Server::start();
        server.file_with(VITS_PATH, body.clone(), &[], ranges);
        server.cut_next(VITS_PATH, 1 << 20);
        let cache = tempfile::tempdir().unwrap();
        let f = fetcher(&server, cache.path());
        let w = vits_entry("vits-mirror", Some(&pinned));
        let e = f.fetch(w).unwrap_err().to_string();
        assert!(e.contains("1048576") && e.contains("fetch again to resume"), "{e}");
        let fetched = f.fetch(w).unwrap();
        assert_eq!((std::fs::read(&fetched.path).unwrap(), fetched.verified), (body.clone(), Verified::PinnedSha256));
        let snapshot = "huggingface/hub/models--depth-anything--Depth-Anything-V2-Small/snapshots/mirror";
        assert_eq!(fetched.path, cache.path().join(snapshot).join("depth_anything_v2_vits.pth"));
        let requests: Vec<_> = server.requests().into_iter().map(|r| (r.path, r.range)).collect();
        // The second request resumed; a server without ranges sent the whole file again.
        assert_eq!(requests.len(), 2, "{requests:?}");
        assert_eq!(requests[1].1.as_deref(), Some("bytes=1048576-"));
    }
}

#[test]
fn a_cached_file_that_changed_is_an_error_naming_it_and_both_hashes() {
    let (Some(default), Some(vits)) =
        (golden("changed", "raft_stereo_random.pth"), golden("changed", "depth_anything_v2_vits_random.pth"))
    else {
        return;
    };
    let server = Server::start();
    serve_models_zip(&server, &[("raftstereo-middlebury.pth", &default)]);
    let body = std::fs::read(&vits).unwrap();
    server.file_with(VITS_PATH, body.clone(), &[], true);
    let cache = tempfile::tempdir().unwrap();
    let f = fetcher(&server, cache.path());
    let pinned = vits_entry("vits-changed", Some(&sha256(&body)));
    for w in [find("raftstereo-middlebury").unwrap(), pinned] {
        let path = f.get(w).unwrap();
        let blob = std::fs::canonicalize(&path).unwrap();
        let original = std::fs::read(&blob).unwrap();
        let modified = std::fs::metadata(&blob).unwrap().modified().unwrap();
        // Touched, not changed: loads and `weights fetch` accept it.
        let file = std::fs::File::options().write(true).open(&blob).unwrap();
        file.set_modified(modified + Duration::from_secs(5)).unwrap();
        drop(file);
        f.get(w).unwrap();
        f.fetch(w).unwrap();
        // Rewritten: the next load hashes it, as its modification time moved.
        let mut bytes = original.clone();
        let last = bytes.len() - 1;
        bytes[last] ^= 0xff;
        std::fs::write(&blob, &bytes).unwrap();
        let e = f.get(w).unwrap_err().to_string();
        assert!(e.contains(&sha256(&original)) && e.contains(&sha256(&bytes)), "{e}");
        assert!(e.contains("changed since it was fetched") && e.contains(&path.display().to_string()), "{e}");
        // Its modification time put back (same size): a load trusts the stamp, `weights fetch`
        // hashes every byte and refuses it.
        let file = std::fs::File::options().write(true).open(&blob).unwrap();
        file.set_modified(modified + Duration::from_secs(5)).unwrap();
        drop(file);
        assert!(f.get(w).is_ok(), "{}: the stamp is what a load compares", w.name);
        assert!(f.fetch(w).unwrap_err().to_string().contains(&sha256(&bytes)));
    }
}
