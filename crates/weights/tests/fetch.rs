//! Fetching named weights from a loopback server that stands in for the hub, for Dropbox and
//! for Google Drive: a good fetch of each source (through a redirect, as the real servers
//! answer; through Drive's confirmation page), an interrupted one resumed, two concurrent
//! fetches of one name, offline mode, a file published on a page, names and options.

mod fixtures;
mod loopback;

use std::path::{Path, PathBuf};

use dgstereo_core::Error;
use dgstereo_prior::depth_anything::DepthAnythingV2Encoder;
use dgstereo_weights::structure::{KeyShape, check_igev, defom_encoder, state_dict_of};
use dgstereo_weights::{Cache, Fetcher, Role, Sources, Verified, find};
use fixtures::*;
use loopback::Server;

#[test]
fn a_hub_file_is_fetched_through_the_redirect_into_the_hugging_face_layout() {
    let Some(vits) = golden("hub_fetch", "depth_anything_v2_vits_random.pth") else { return };
    let body = std::fs::read(&vits).unwrap();
    let server = Server::start();
    serve_hub_file(&server, body.clone(), &format!("\"{}\"", sha256(&body)));
    let cache = tempfile::tempdir().unwrap();
    let f = fetcher(&server, cache.path());
    let w = vits_entry("vits-hub", None);
    let fetched = f.fetch(w).unwrap();
    let expected = format!(
        "huggingface/hub/models--depth-anything--Depth-Anything-V2-Small/snapshots/{COMMIT}/depth_anything_v2_vits.pth"
    );
    assert_eq!((fetched.path.clone(), fetched.verified), (cache.path().join(expected), Verified::ServerSha256));
    assert_eq!(std::fs::read(&fetched.path).unwrap(), body);
    // Cached: found offline, with the server's requests unchanged.
    let before = server.requests().len();
    let again = f.clone().offline(true).get(w).unwrap();
    assert_eq!((again, server.requests().len()), (fetched.path.clone(), before));
    // Another cache that shares this one as its Hugging Face cache (as Python's) finds it too.
    let other = tempfile::tempdir().unwrap();
    let shared = Cache::at(other.path().to_path_buf()).with_shared_hub(cache.path().join("huggingface/hub"));
    assert_eq!(shared.find(w), Some(fetched.path));
}

#[test]
fn models_zip_is_fetched_through_a_redirect_and_each_checkpoint_kept_and_recorded() {
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
    // One download gave both, each with its SHA-256 recorded; the archive itself is not kept.
    let sceneflow =
        f.clone().offline(true).resolve(Path::new("raftstereo-sceneflow"), Role::Stereo, "weights").unwrap();
    assert_eq!(std::fs::read(sceneflow).unwrap(), std::fs::read(&default).unwrap());
    assert_eq!(files_under(&cache.path().join("raft-stereo")), ["raftstereo-realtime.pth", "raftstereo-sceneflow.pth"]);
    let recorded = f.cache().recorded(find("raftstereo-realtime").unwrap()).unwrap().map(|r| r.sha256);
    assert_eq!(recorded, Some(sha256(&std::fs::read(&realtime).unwrap())));
    // A name the archive lacked is an error after the download, not a file.
    let e = f.resolve(Path::new("raftstereo-eth3d"), Role::Stereo, "weights").unwrap_err();
    assert!(matches!(e.root(), Error::Fetch { .. }) && e.to_string().contains("raftstereo-eth3d.pth"), "{e}");
}

/// Drive's confirmation page for a file too large to scan, naming `file`, whose form asks for
/// `/download?id=ID&export=download&confirm=t&uuid=UUID` of `base`.
fn confirmation_page(base: &str, id: &str, file: &str) -> String {
    format!(
        "<!DOCTYPE html><html><head><title>Google Drive - Virus scan warning</title></head><body>\
         <p class=\"uc-warning-subcaption\">Google Drive can't scan this file for viruses.</p>\
         <span class=\"uc-name-size\"><a href=\"/open?id={id}\">{file}</a> (42M)</span>\
         <form id=\"download-form\" action=\"{base}/download\" method=\"get\">\
         <input type=\"submit\" id=\"uc-download-link\" class=\"goog-inline-block\" value=\"Download anyway\"/>\
         <input type=\"hidden\" name=\"id\" value=\"{id}\"><input type=\"hidden\" name=\"export\" value=\"download\">\
         <input type=\"hidden\" name=\"confirm\" value=\"t\"><input type=\"hidden\" name=\"uuid\" value=\"u-{id}\">\
         </form></body></html>"
    )
}

#[test]
fn a_google_drive_file_is_found_by_name_through_the_confirmation_page_and_resumed() {
    let Some(default) = golden("drive_fetch", "raft_stereo_random.pth") else { return };
    let body = std::fs::read(&default).unwrap();
    let server = Server::start();
    // Two ids without names, as the release script lists them: the first is another file.
    for (id, file) in [("A1", "other_model.pth"), ("B2", "raft_test.pth")] {
        server.page(&format!("/download?id={id}&export=download"), &confirmation_page(server.base(), id, file));
    }
    let confirmed = "/download?id=B2&export=download&confirm=t&uuid=u-B2";
    let disposition = "attachment; filename=\"raft_test.pth\"; filename*=UTF-8''raft_test.pth";
    server.file_with(confirmed, body.clone(), &[("Content-Disposition", disposition)], true);
    let cache = tempfile::tempdir().unwrap();
    let f = fetcher(&server, cache.path());
    let w = drive_entry("raft-drive", "raft_test.pth", &["A1", "B2"]);
    server.cut_next(confirmed, 1 << 20);
    let e = f.fetch(w).unwrap_err();
    assert!(matches!(e.root(), Error::Fetch { url, .. } if url.ends_with(confirmed)), "{e}");
    let fetched = f.fetch(w).unwrap();
    assert_eq!(fetched.path, cache.path().join("google-drive/raft_test.pth"));
    assert_eq!((std::fs::read(&fetched.path).unwrap(), fetched.verified), (body.clone(), Verified::StructureOnly));
    assert_eq!(f.cache().recorded(w).unwrap().map(|r| r.sha256), Some(sha256(&body)));
    let requests = server.requests();
    // The other file's body was never asked for; the second attempt resumed.
    assert!(!requests.iter().any(|r| r.path.contains("confirm=t&uuid=u-A1")), "{requests:?}");
    let last = requests.iter().rev().find(|r| r.path == confirmed).unwrap();
    assert_eq!(last.range.as_deref(), Some("bytes=1048576-"));
    // No id serving the name is an error naming what they serve.
    let e = f.fetch(drive_entry("missing", "absent.pth", &["A1"])).unwrap_err().to_string();
    assert!(e.contains("absent.pth") && e.contains("A1: other_model.pth"), "{e}");
    // A page without the form (a quota page) is an error quoting it.
    server.page(
        "/download?id=Q&export=download",
        "<html><head><title>Google Drive - Quota exceeded</title></head><body>\
         <p class=\"uc-error-subcaption\">Too many users have viewed or downloaded this file recently.</p></body></html>",
    );
    let e = f.fetch(drive_entry("quota", "q.pth", &["Q"])).unwrap_err().to_string();
    assert!(e.contains("Quota exceeded") && e.contains("Too many users"), "{e}");
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
    serve_hub_file(&server, body.clone(), &format!("\"{}\"", sha256(&body)));
    let cache = tempfile::tempdir().unwrap();
    let f = fetcher(&server, cache.path());
    let vits_w = vits_entry("vits-resume", None);
    for (w, cdn, len) in
        [(find("raftstereo-sceneflow").unwrap(), "/cdn/models.zip", zip.len()), (vits_w, "/cdn/vits", body.len())]
    {
        server.cut_next(cdn, 3 << 20);
        let e = f.fetch(w).unwrap_err().to_string();
        assert!(f.cache().find(w).is_none(), "{}: a broken download left a file: {e}", w.name);
        assert!(e.contains("fetch again to resume"), "{e}");
        assert!(f.fetch(w).unwrap().path.is_file());
        // The second full request asked for the rest only.
        let ranges: Vec<_> = server.requests().into_iter().filter(|r| r.path == cdn).filter_map(|r| r.range).collect();
        let resumed = ranges.iter().filter_map(|r| r.strip_prefix("bytes=")?.strip_suffix('-')?.parse::<usize>().ok());
        assert!(resumed.clone().any(|from| from >= 3 << 20 && from < len), "{}: {ranges:?}", w.name);
    }
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
    let e = f.resolve(Path::new("raftstereo-middlebury"), Role::Stereo, "weights").unwrap_err();
    assert!(matches!(e.root(), Error::Fetch { .. }), "{e}");
    let e = e.to_string();
    assert!(e.contains("dgstereo weights fetch raftstereo-middlebury") && e.contains("offline"), "{e}");
    assert!(server.requests().is_empty());
}

#[test]
fn a_file_published_on_a_page_says_where_to_get_it_and_is_checked_where_placed() {
    let Some(default) = golden("page_fetch", "raft_stereo_random.pth") else { return };
    let cache = tempfile::tempdir().unwrap();
    let f = Fetcher::new(Cache::at(cache.path().to_path_buf()), Sources::default());
    let igev = find("igev-stereo-sceneflow").unwrap();
    let e = f.get(igev).unwrap_err();
    let place = cache.path().join("igev-stereo-sceneflow/sceneflow.pth");
    assert!(matches!(e, Error::Unsupported { .. }), "{e}");
    let text = e.to_string();
    assert!(text.contains("drive.google.com/drive/folders/") && text.contains(&place.display().to_string()), "{text}");
    // A RAFT-Stereo file placed there is no IGEV-Stereo checkpoint.
    std::fs::create_dir_all(place.parent().unwrap()).unwrap();
    std::fs::copy(&default, &place).unwrap();
    let e = f.get(igev).unwrap_err().to_string();
    assert!(e.contains("'cost_agg.*'") && e.contains("not an IGEV-Stereo checkpoint"), "{e}");
    assert_eq!(f.cache().recorded(igev).unwrap(), None);
}

#[test]
fn a_weights_option_takes_every_stereo_name_on_to_its_source() {
    let server = Server::start();
    let cache = tempfile::tempdir().unwrap();
    let f = fetcher(&server, cache.path());
    // Every stereo name has a network here, so none is refused for its architecture.
    for w in dgstereo_weights::CATALOG.iter().filter(|w| w.role == Role::Stereo) {
        assert_eq!(w.architecture.unloadable_reason(), None, "{}", w.name);
    }
    // The IGEV-Stereo name goes on to its page: where to download the file and where to put it,
    // without a request to any server.
    let e = f.resolve_stereo(Path::new("igev-stereo-sceneflow"), "weights").unwrap_err();
    let place = cache.path().join("igev-stereo-sceneflow/sceneflow.pth");
    let text = e.to_string();
    assert!(text.contains("drive.google.com/drive/folders/") && text.contains(&place.display().to_string()), "{text}");
    assert!(server.requests().is_empty(), "{:?}", server.requests());
    // A DEFOM-Stereo name goes on to the fetch (here a server that has no such file).
    let e = f.resolve_stereo(Path::new("defomstereo-vits-sceneflow"), "weights").unwrap_err();
    assert!(matches!(e.root(), Error::Fetch { .. }), "{e}");
    assert!(!server.requests().is_empty());
}

#[test]
fn names_go_to_their_option_and_unknown_names_list_the_known_ones() {
    let cache = tempfile::tempdir().unwrap();
    let f = Fetcher::new(Cache::at(cache.path().to_path_buf()), Sources::default()).offline(true);
    let e = f.resolve(Path::new("depth-anything-v2-base"), Role::Stereo, "weights").unwrap_err().to_string();
    assert!(e.contains("--prior-weights"), "{e}");
    let e = f.resolve(Path::new("raftstereo-eth3d"), Role::Prior, "prior").unwrap_err().to_string();
    assert!(e.contains("--weights"), "{e}");
    let e = f.resolve(Path::new("raftstereo-kitti"), Role::Stereo, "weights").unwrap_err().to_string();
    assert!(e.contains("raftstereo-middlebury") && e.contains("defomstereo-vitl-kitti"), "{e}");
    // A path that does not exist is left for the loader to report; a name left unresolved is
    // refused by the libraries that take files.
    let missing = cache.path().join("mine.pth");
    assert_eq!(f.resolve(&missing, Role::Stereo, "weights").unwrap(), missing);
    assert!(dgstereo_weights::check_resolved(&missing, "weights").is_ok());
    let e = dgstereo_weights::check_resolved(Path::new("raftstereo-eth3d"), "weights").unwrap_err();
    assert!(matches!(&e, Error::Config(p) if p.key == "weights"), "{e}");
    // Which entry an option is: a name in any spelling, or a file under an entry's file name.
    let named = |spec: &str| dgstereo_weights::named_by(Path::new(spec)).map(|w| w.name);
    assert_eq!(named("RAFTSTEREO_SCENEFLOW"), Some("raftstereo-sceneflow"));
    assert_eq!(named("/cache/google-drive/defomstereo_vits_sceneflow.pth"), Some("defomstereo-vits-sceneflow"));
    assert_eq!(named("models/raftstereo-middlebury.pth"), Some("raftstereo-middlebury"));
    assert_eq!(named("mine.pth"), None);
    assert_eq!(named("checkpoints/raftstereo-sceneflow"), None);
}

/// The official state dict's keys and shapes that a seeded golden file lists in its metadata.
fn golden_keys(test: &str, file: &str) -> Option<Vec<KeyShape>> {
    let bytes = std::fs::read(golden(test, file)?).unwrap();
    let n = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
    let header: serde_json::Value = serde_json::from_slice(&bytes[8..8 + n]).unwrap();
    Some(serde_json::from_str(header["__metadata__"]["keys"].as_str().unwrap()).unwrap())
}

#[test]
fn defom_and_igev_state_dicts_are_told_apart_and_the_vit_width_read() {
    let (Some(defom), Some(igev)) = (
        golden_keys("structure", "defom_stereo_vits_seeded.activations.safetensors"),
        golden_keys("structure", "igev_stereo_seeded.activations.safetensors"),
    ) else {
        return;
    };
    assert_eq!(defom_encoder(&defom), Ok(DepthAnythingV2Encoder::Vits));
    check_igev(&igev).unwrap();
    // As the official checkpoints may hold them: under `module.`, inside a training wrapper.
    let wrapped: Vec<KeyShape> = defom.iter().map(|(k, s)| (format!("model.module.{k}"), s.clone())).collect();
    assert_eq!(defom_encoder(&state_dict_of(wrapped)), Ok(DepthAnythingV2Encoder::Vits));
    let prefixed: Vec<KeyShape> = igev.iter().map(|(k, s)| (format!("module.{k}"), s.clone())).collect();
    check_igev(&state_dict_of(prefixed)).unwrap();
    // Each is not the other; a DEFOM-Stereo without its scale update is none.
    assert!(check_igev(&defom).unwrap_err().contains("'cost_agg.*'"));
    assert!(defom_encoder(&igev).unwrap_err().contains("'defomencoder.depth_anything.pretrained.*'"));
    let cut: Vec<KeyShape> = defom.iter().filter(|(k, _)| !k.starts_with("scale_update_block.")).cloned().collect();
    assert!(defom_encoder(&cut).unwrap_err().contains("'scale_update_block.*'"));
    // A wider token than ViT-S's with ViT-S's blocks is refused, naming the key.
    let widened: Vec<KeyShape> =
        defom
            .iter()
            .map(|(k, s)| {
                if k.ends_with("pretrained.cls_token") { (k.clone(), vec![1, 1, 1024]) } else { (k.clone(), s.clone()) }
            })
            .collect();
    assert!(defom_encoder(&widened).unwrap_err().contains("blocks"));
    for w in dgstereo_weights::CATALOG.iter().filter(|w| w.name.starts_with("defomstereo-vits")) {
        assert_eq!(w.architecture, dgstereo_weights::Architecture::DefomStereo(DepthAnythingV2Encoder::Vits));
    }
}
