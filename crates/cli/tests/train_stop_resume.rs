//! A training run stopped by a signal, and what `--resume` accepts: SIGINT finishes the step,
//! writes its checkpoint and exits 130; the resumed run ends with a `model.safetensors` equal
//! byte for byte to an uninterrupted run's; `--resume` with another training configuration is
//! refused, naming the key, and touches nothing. SIGTERM delivered twice at once (coreutils
//! `timeout`, a signal to the process group) is one stop with a checkpoint; a second SIGINT a
//! second later stops at once and says what it dropped; a stopped `ablate` says to run the same
//! command again, which finishes the study.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::{SYNTHETIC_SOURCE, TINY_VALIDATION, dgstereo, text, tiny_train, write_experiment};

/// Spawns `dgstereo args`, with its output captured.
fn spawn(args: &[&str]) -> std::process::Child {
    Command::new(env!("CARGO_BIN_EXE_dgstereo"))
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// Waits until the log at `out` holds `lines` training lines of `child`'s run.
fn wait_for_steps(child: &mut std::process::Child, out: &Path, lines: usize) {
    let started = Instant::now();
    while train_lines(out) < lines {
        assert!(started.elapsed() < Duration::from_secs(120), "no training step logged in 120 s");
        if let Some(status) = child.try_wait().unwrap() {
            let mut said = String::new();
            std::io::Read::read_to_string(child.stderr.as_mut().unwrap(), &mut said).unwrap();
            panic!("the run ended ({status}) before logging {lines} steps: {said}");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Sends `signals` (`"TERM TERM"`) to process `pid` from one shell, as fast as it can.
fn send(pid: u32, signals: &str) {
    let script: Vec<String> = signals.split_whitespace().map(|s| format!("kill -{s} {pid}")).collect();
    assert!(Command::new("sh").args(["-c", &script.join("; ")]).status().unwrap().success());
}

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

    let mut child = spawn(&["train", exp.to_str().unwrap(), "--out", stopped.to_str().unwrap(), "--quiet"]);
    wait_for_steps(&mut child, &stopped, 2);
    send(child.id(), "INT");
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

#[cfg(unix)]
#[test]
fn sigterm_delivered_twice_is_one_stop_with_a_checkpoint_and_resume_continues() {
    let dir = tempfile::tempdir().unwrap();
    let exp = experiment(dir.path(), "twice.toml", 40, "4e-4");
    let out = dir.path().join("run");
    let mut child = spawn(&["train", exp.to_str().unwrap(), "--out", out.to_str().unwrap(), "--quiet"]);
    wait_for_steps(&mut child, &out, 2);
    send(child.id(), "TERM TERM");
    let output = child.wait_with_output().unwrap();
    let all = text(&output);
    assert_eq!(output.status.code(), Some(143), "{all}");
    let reached = train_lines(&out);
    assert!(reached < 40, "the run finished before the signal: {all}");
    assert!(all.contains("SIGTERM: stopping after the current step, with a checkpoint"), "{all}");
    assert!(all.contains(&format!("stopped at step {reached}, checkpoint written")), "{all}");
    assert!(!all.contains("stopped at once"), "{all}");
    assert!(out.join(format!("checkpoints/step-{reached:08}.safetensors")).is_file(), "{all}");
    let resumed = dgstereo(&["train", exp.to_str().unwrap(), "--out", out.to_str().unwrap(), "--resume", "--quiet"]);
    let said = text(&resumed);
    assert!(resumed.status.success(), "{said}");
    assert!(said.contains(&format!("resuming at step {reached}")) && out.join("model.safetensors").is_file(), "{said}");
}

#[cfg(unix)]
#[test]
fn a_second_sigint_a_second_later_stops_at_once_and_says_what_it_drops() {
    let dir = tempfile::tempdir().unwrap();
    // A validation after every step on a large pair with many iterations: seconds long, so the
    // second signal arrives while the first waits for it to end.
    let train = tiny_train(40, 1, 5, 1000, "").replace("validate_every = 0", "validate_every = 1");
    let validation = "[data.validation]\ncount = 1\nwidth = 1024\nheight = 512\niters = 32\n";
    let exp = write_experiment(dir.path(), "slow.toml", "slow", &train, &format!("{SYNTHETIC_SOURCE}{validation}"), "");
    let out = dir.path().join("run");
    let mut child = spawn(&["train", exp.to_str().unwrap(), "--out", out.to_str().unwrap(), "--quiet"]);
    wait_for_steps(&mut child, &out, 1);
    send(child.id(), "INT");
    std::thread::sleep(Duration::from_millis(1300));
    assert!(child.try_wait().unwrap().is_none(), "the validation ended within 1.3 s: the test needs a longer one");
    send(child.id(), "INT");
    let output = child.wait_with_output().unwrap();
    let all = text(&output);
    assert_eq!(output.status.code(), Some(130), "{all}");
    assert!(all.contains("SIGINT again: stopped at once; dropped step 1"), "{all}");
    assert!(all.contains("no checkpoint was written yet"), "{all}");
    assert!(!out.join("checkpoints/step-00000001.safetensors").exists());
}

#[cfg(unix)]
#[test]
fn a_stopped_ablate_says_to_run_the_same_command_again_which_finishes_it() {
    let dir = tempfile::tempdir().unwrap();
    let exp = experiment(dir.path(), "study.toml", 40, "4e-4");
    let out = dir.path().join("study");
    let args = ["ablate", exp.to_str().unwrap(), "--out", out.to_str().unwrap(), "--quiet"];
    let mut child = spawn(&args);
    wait_for_steps(&mut child, &out.join("stop"), 2);
    send(child.id(), "TERM");
    let output = child.wait_with_output().unwrap();
    let all = text(&output);
    assert_eq!(output.status.code(), Some(143), "{all}");
    assert!(all.contains("checkpoint written") && all.contains("run the same command again"), "{all}");
    assert!(!all.contains("--resume"), "ablate has no --resume: {all}");
    let again = dgstereo(&args);
    let said = text(&again);
    assert!(again.status.success(), "{said}");
    assert!(said.contains("resuming at step") && out.join("ablation.md").is_file(), "{said}");
}
