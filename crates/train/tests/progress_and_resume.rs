//! A run reports its progress as events (the library draws nothing), and `resume` finishes what
//! is unfinished, starts what never started and leaves a finished run as it is, its
//! `summary.json` included.

mod common;

use std::path::Path;
use std::sync::{Arc, Mutex};

use dgstereo_core::default_device;
use dgstereo_experiment::ValidationConfig;
use dgstereo_train::run::{RunOptions, train};
use dgstereo_train::{Progress, ProgressObserver};

fn options(out: &Path, resume: bool, stop_after: Option<usize>, observer: Option<ProgressObserver>) -> RunOptions {
    RunOptions { out: out.to_path_buf(), resume, stop_after, progress: observer, notice: |_| {}, stop: None }
}

/// An observer and the events it collected.
fn collector() -> (ProgressObserver, Arc<Mutex<Vec<Progress>>>) {
    let events = Arc::new(Mutex::new(Vec::new()));
    let seen = Arc::clone(&events);
    (ProgressObserver::new(move |e| seen.lock().unwrap().push(e.clone())), events)
}

/// The events in short: `S0/4`, `1`, `2*` (a logged step), `V2`, `C2`, `E+` (finished) or `E-`.
fn shorthand(events: &[Progress]) -> Vec<String> {
    events
        .iter()
        .map(|e| match e {
            Progress::Started { done, steps } => format!("S{done}/{steps}"),
            Progress::Step { done, logged } => format!("{done}{}", if logged.is_some() { "*" } else { "" }),
            Progress::Validated { done, .. } => format!("V{done}"),
            Progress::Checkpoint { done, .. } => format!("C{done}"),
            Progress::Ended { finished } => format!("E{}", if *finished { "+" } else { "-" }),
        })
        .collect()
}

#[test]
fn a_run_reports_its_progress_and_resume_leaves_a_finished_run_as_it_is() {
    let device = default_device();
    let mut parts = common::tiny_parts(4, 1, 1e-3, Some(1), 1);
    parts.train.log_every = 2;
    parts.train.checkpoint_every = 2;
    parts.train.validate_every = 2;
    parts.data.validation = ValidationConfig { count: 1, iters: 1, ..ValidationConfig::default() };
    parts.data.validation.scenes.width = 64;
    parts.data.validation.scenes.height = 32;
    let dir = tempfile::tempdir().unwrap();
    let (stopped, fresh) = (dir.path().join("stopped"), dir.path().join("fresh"));

    let (observer, events) = collector();
    let first = train(parts.clone(), &device, &options(&stopped, false, Some(3), Some(observer))).unwrap();
    assert!(!first.finished && first.steps == 3);
    assert_eq!(shorthand(&events.lock().unwrap()), ["S0/4", "1", "2*", "V2", "C2", "3*", "C3", "E-"]);

    let (observer, events) = collector();
    let done = train(parts.clone(), &device, &options(&stopped, true, None, Some(observer))).unwrap();
    assert!(done.finished && !done.untouched && done.steps == 4);
    assert_eq!(shorthand(&events.lock().unwrap()), ["S3/4", "4*", "V4", "C4", "E+"]);
    let Progress::Validated { metrics, .. } = &events.lock().unwrap()[2] else { panic!("a validation") };
    assert_eq!(done.validation.map(|m| m.epe), Some(metrics.epe));

    // Resuming the finished run changes nothing, and says what it holds.
    let files = ["summary.json", "model.safetensors", "log.jsonl", "config.toml"];
    let before: Vec<Vec<u8>> = files.iter().map(|f| std::fs::read(stopped.join(f)).unwrap()).collect();
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(stopped.join("summary.json")).unwrap()).unwrap();
    assert!(summary["last_train"]["loss"].is_number() && summary["validation"]["epe"].is_number(), "{summary}");
    let (observer, events) = collector();
    let again = train(parts.clone(), &device, &options(&stopped, true, None, Some(observer))).unwrap();
    assert!(again.finished && again.untouched && again.steps == 4);
    assert!(events.lock().unwrap().is_empty(), "nothing ran");
    assert_eq!(again.validation.map(|m| m.epe), done.validation.map(|m| m.epe), "the log's last validation");
    assert_eq!(again.last.map(|r| r.loss), done.last.map(|r| r.loss));
    let after: Vec<Vec<u8>> = files.iter().map(|f| std::fs::read(stopped.join(f)).unwrap()).collect();
    assert!(before == after, "resuming a finished run rewrote its files");

    // Another training configuration is refused even for a finished run.
    let mut other = parts.clone();
    other.resolved_toml = "[train]\nlr = 0.5\n".into();
    let e = train(other, &device, &options(&stopped, true, None, None)).unwrap_err().to_string();
    assert!(e.contains("train.lr") && e.contains("nothing was changed"), "{e}");

    // A folder with no checkpoint: resume starts the run there, and ends as an uninterrupted run.
    let started = train(parts, &device, &options(&fresh, true, None, None)).unwrap();
    assert!(started.finished && started.steps == 4);
    assert_eq!(
        std::fs::read(fresh.join("model.safetensors")).unwrap(),
        std::fs::read(stopped.join("model.safetensors")).unwrap(),
        "the run started by resume equals the stopped and resumed one"
    );
}
