//! `train SWEEP.toml --resume` as a user runs it after an interruption: the finished run is left
//! as it is, the stopped one resumes, the one that never started starts, and each ends equal
//! byte for byte to an uninterrupted sweep's; resuming the finished sweep changes nothing and
//! exits 0, `summary.json` included.

mod common;

use std::path::{Path, PathBuf};

use common::{SYNTHETIC_SOURCE, TINY_VALIDATION, dgstereo, text, tiny_train, write_experiment};

/// Every file under `dir` with its bytes, sorted by path.
fn snapshot(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut files = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else {
                files.push((path.strip_prefix(dir).unwrap().to_path_buf(), std::fs::read(&path).unwrap()));
            }
        }
    }
    files.sort();
    files
}

fn copy_tree(from: &Path, to: &Path) {
    for (relative, bytes) in snapshot(from) {
        let path = to.join(relative);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(path, bytes).unwrap();
    }
}

#[test]
fn resume_finishes_a_sweep_however_far_it_got() {
    let dir = tempfile::tempdir().unwrap();
    let train = tiny_train(3, 1, 7, 2, "");
    let data = format!("{SYNTHETIC_SOURCE}{TINY_VALIDATION}");
    let exp =
        write_experiment(dir.path(), "sweep.toml", "sweep", &train, &data, "[sweep]\n\"train.seed\" = [1, 2, 3]\n");
    let whole = dir.path().join("whole");
    let o = dgstereo(&["train", exp.to_str().unwrap(), "--out", whole.to_str().unwrap(), "--quiet"]);
    assert!(o.status.success(), "{}", text(&o));
    let runs: Vec<String> = (1..=3).map(|s| format!("sweep_train.seed={s}")).collect();

    // An interrupted sweep: the first run finished, the second stopped after its checkpoint of
    // step 2, the third never started.
    let partial = dir.path().join("partial");
    copy_tree(&whole, &partial);
    let second = partial.join(&runs[1]);
    for file in ["model.safetensors", "summary.json", "checkpoints/step-00000003.safetensors"] {
        std::fs::remove_file(second.join(file)).unwrap();
    }
    std::fs::remove_dir_all(partial.join(&runs[2])).unwrap();
    let first = snapshot(&partial.join(&runs[0]));

    let o = dgstereo(&["train", exp.to_str().unwrap(), "--out", partial.to_str().unwrap(), "--quiet"]);
    assert!(!o.status.success() && text(&o).contains("already holds checkpoints"), "{}", text(&o));
    let o = dgstereo(&["train", exp.to_str().unwrap(), "--out", partial.to_str().unwrap(), "--quiet", "--resume"]);
    let said = text(&o);
    assert!(o.status.success(), "{said}");
    assert!(said.contains("sweep/train.seed=1: finished run in") && said.contains("left as it is"), "{said}");
    assert!(said.contains("resuming at step 2"), "{said}");
    assert!(said.contains("holds no checkpoint: starting the run"), "{said}");
    assert!(snapshot(&partial.join(&runs[0])) == first, "the finished run was touched");
    for run in &runs[1..] {
        let model = |root: &Path| std::fs::read(root.join(run).join("model.safetensors")).unwrap();
        assert!(model(&partial) == model(&whole), "{run} differs from the uninterrupted sweep's");
        let summary: serde_json::Value =
            serde_json::from_slice(&std::fs::read(partial.join(run).join("summary.json")).unwrap()).unwrap();
        assert!(summary["last_train"]["loss"].is_number() && summary["validation"]["epe"].is_number(), "{summary}");
    }

    // Resuming the finished sweep: exit 0, nothing changes (summary.json keeps its values).
    let before = snapshot(&partial);
    let o = dgstereo(&["train", exp.to_str().unwrap(), "--out", partial.to_str().unwrap(), "--quiet", "--resume"]);
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(text(&o).matches("left as it is").count(), 3, "{}", text(&o));
    assert!(snapshot(&partial) == before, "resuming a finished sweep changed its files");
}
