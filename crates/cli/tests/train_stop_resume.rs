//! A training run stopped by a signal, and what `--resume` accepts: SIGINT finishes the step,
//! writes its checkpoint and exits 130; the resumed run ends with a `model.safetensors` equal
//! byte for byte to an uninterrupted run's; `--resume` with another training configuration is
//! refused, naming the key, and touches nothing.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::{SYNTHETIC_SOURCE, TINY_VALIDATION, dgstereo, text, tiny_train, write_experiment};

/// A tiny run of `steps` steps that checkpoints only at its end, with learning rate `lr`.
fn experiment(dir: &Path, file: &str, steps: usize, lr: &str) -> PathBuf {
    let train = tiny_train(steps, 1, 5, 1000, &format!("lr = {lr}\n"));
    write_experiment(dir, file, "stop", &train, &format!("{SYNTHETIC_SOURCE}{TINY_VALIDATION}"), "")
}

fn train_lines(out: &Path) -> usize {
    std::fs::read_to_string(out.join("log.jsonl")).map_or(0, |l| l.lines().filter(|l| l.contains("\"train\"")).count())
}

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
                files.push((path.clone(), std::fs::read(&path).unwrap()));
            }
        }
    }
    files.sort();
    files
}

#[cfg(unix)]
#[test]
fn sigint_checkpoints_the_step_reached_and_the_resumed_run_equals_an_uninterrupted_one() {
    let dir = tempfile::tempdir().unwrap();
    let steps = 40;
    let exp = experiment(dir.path(), "stop.toml", steps, "4e-4");
    let (stopped, whole) = (dir.path().join("stopped"), dir.path().join("whole"));

    let child = Command::new(env!("CARGO_BIN_EXE_dgstereo"))
        .args(["train", exp.to_str().unwrap(), "--out", stopped.to_str().unwrap(), "--quiet"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let started = Instant::now();
    while train_lines(&stopped) < 2 {
        assert!(started.elapsed() < Duration::from_secs(120), "no training step logged in 120 s");
        std::thread::sleep(Duration::from_millis(20));
    }
    let kill = Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap();
    assert!(kill.success());
    let output = child.wait_with_output().unwrap();
    let all = text(&output);
    assert_eq!(output.status.code(), Some(130), "{all}");
    let reached = train_lines(&stopped);
    assert!(reached < steps, "the run finished before the signal: {all}");
    assert!(all.contains(&format!("stopped at step {reached}, checkpoint written")), "{all}");
    assert!(stopped.join(format!("checkpoints/step-{reached:08}.safetensors")).is_file(), "{all}");
    assert!(!stopped.join("model.safetensors").exists());

    // Another learning rate is another run: refused, naming the key, nothing touched.
    let other = experiment(dir.path(), "other.toml", steps, "2e-4");
    let before = snapshot(&stopped);
    let refused = dgstereo(&["train", other.to_str().unwrap(), "--out", stopped.to_str().unwrap(), "--resume"]);
    let said = text(&refused);
    assert!(!refused.status.success(), "{said}");
    assert!(said.contains("train.lr: 0.0002 here, 0.0004 in the run"), "{said}");
    assert!(snapshot(&stopped) == before, "--resume with another configuration changed the folder");

    let resumed =
        dgstereo(&["train", exp.to_str().unwrap(), "--out", stopped.to_str().unwrap(), "--resume", "--quiet"]);
    let said = text(&resumed);
    assert!(resumed.status.success(), "{said}");
    assert!(said.contains(&format!("resuming at step {reached}")), "{said}");
    let uninterrupted = dgstereo(&["train", exp.to_str().unwrap(), "--out", whole.to_str().unwrap(), "--quiet"]);
    assert!(uninterrupted.status.success(), "{}", text(&uninterrupted));
    let (a, b) = (
        std::fs::read(stopped.join("model.safetensors")).unwrap(),
        std::fs::read(whole.join("model.safetensors")).unwrap(),
    );
    assert!(a == b, "the resumed run's model.safetensors differs in bytes from the uninterrupted run's");
}
